//! A client's outgoing messages: a queue bounded in bytes, which the client's writer (a thread
//! of its own, or the WebSocket's loop) empties and the server fills (`Server::send`,
//! `Server::send_reply`), with how long it has been since the client last took a message.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// One client's outgoing messages, bounded in bytes.
pub(super) struct Outbox {
    queue: Mutex<OutboxQueue>,
    ready: Condvar,
}

struct OutboxQueue {
    messages: VecDeque<Arc<str>>,
    bytes: usize,
    closed: bool,
    /// When a message was last taken off (or the queue was last empty): a client that reads.
    progress: Instant,
}

impl Outbox {
    pub(super) fn new() -> Outbox {
        let queue = OutboxQueue { messages: VecDeque::new(), bytes: 0, closed: false, progress: Instant::now() };
        Outbox { queue: Mutex::new(queue), ready: Condvar::new() }
    }

    /// Queues `message` when it keeps the queue within `max_bytes` (or the queue is empty: one
    /// message larger than the bound still goes); else gives the bytes already queued.
    pub(super) fn push(&self, message: Arc<str>, max_bytes: usize) -> Result<(), usize> {
        let mut queue = self.queue.lock().expect("client queue");
        let fits = queue.messages.is_empty() || queue.bytes + message.len() <= max_bytes;
        if queue.closed || !fits {
            return Err(queue.bytes);
        }
        if queue.messages.is_empty() {
            queue.progress = Instant::now();
        }
        queue.bytes += message.len();
        queue.messages.push_back(message);
        self.ready.notify_one();
        Ok(())
    }

    /// The next message, waiting for one; `None` once the queue is closed and sent.
    pub(super) fn pop(&self) -> Option<Arc<str>> {
        let mut queue = self.queue.lock().expect("client queue");
        loop {
            if let Some(message) = queue.pop() {
                return Some(message);
            }
            if queue.closed {
                return None;
            }
            queue = self.ready.wait(queue).expect("client queue");
        }
    }

    /// The next message if one is queued; `Err` once the queue is closed and sent.
    pub(super) fn try_pop(&self) -> Result<Option<Arc<str>>, ()> {
        let mut queue = self.queue.lock().expect("client queue");
        match queue.pop() {
            Some(message) => Ok(Some(message)),
            None if queue.closed => Err(()),
            None => Ok(None),
        }
    }

    pub(super) fn close(&self) {
        self.queue.lock().expect("client queue").closed = true;
        self.ready.notify_all();
    }

    /// The bytes queued, and how long since the client last took a message.
    pub(super) fn backlog(&self) -> (usize, Duration) {
        let queue = self.queue.lock().expect("client queue");
        (queue.bytes, queue.progress.elapsed())
    }
}

impl OutboxQueue {
    fn pop(&mut self) -> Option<Arc<str>> {
        let message = self.messages.pop_front()?;
        self.bytes -= message.len();
        self.progress = Instant::now();
        Some(message)
    }
}
