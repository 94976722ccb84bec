//! The hot-reload protocol against hostile and careless clients (hardening, fourth round): a
//! client that asks without reading, slow and half-open handshakes, pages from other sites,
//! pages that vanish, clients that only ping, and WebSocket messages that break the rules.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::Value;
use tungstenite::protocol::frame::coding::{CloseCode, Data, OpCode};
use tungstenite::protocol::frame::Frame;
use tungstenite::Message;

use crate::watch::{watched_project, Daemon};

/// The daemon's resident memory in MiB.
fn resident_mib(daemon: &Daemon) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", daemon.child.id())).unwrap();
    let line = status.lines().find(|line| line.starts_with("VmRSS:")).unwrap().to_string();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() / 1024
}

type Socket = tungstenite::WebSocket<TcpStream>;

/// A WebSocket handshake with the daemon, sending `origin` when given: the socket, or the
/// refusal's HTTP status.
fn websocket(daemon: &Daemon, origin: Option<&str>) -> Result<Socket, u16> {
    use tungstenite::client::IntoClientRequest;
    let stream = TcpStream::connect(&daemon.address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let mut request = format!("ws://{}/", daemon.address).into_client_request().unwrap();
    if let Some(origin) = origin {
        request.headers_mut().insert("Origin", origin.parse().unwrap());
    }
    match tungstenite::client(request, stream) {
        Ok((socket, _)) => Ok(socket),
        Err(tungstenite::HandshakeError::Failure(tungstenite::Error::Http(response))) => {
            Err(response.status().as_u16())
        }
        Err(error) => panic!("handshake: {error}"),
    }
}

/// The next text message as JSON, or the close frame's code.
fn next_message(socket: &mut Socket) -> Result<Value, Option<CloseCode>> {
    loop {
        match socket.read() {
            Ok(Message::Text(text)) => return Ok(serde_json::from_str(text.as_str()).unwrap()),
            Ok(Message::Close(frame)) => return Err(frame.map(|frame| frame.code)),
            Ok(_) => {}
            Err(error) => {
                println!("read: {error}");
                return Err(None);
            }
        }
    }
}

/// A subscribed client of a fresh daemon on the watched project, and the size of a `state`
/// reply in bytes (its line).
fn daemon_and_state_size(project: &crate::support::TempProject) -> (Daemon, crate::watch::Client, usize) {
    let daemon = Daemon::start(project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    client.send(r#"{"type":"state"}"#);
    let reply = client.receive();
    assert_eq!(reply["type"], "state", "{reply}");
    let bytes = serde_json::to_string(&reply).unwrap().len() + 1;
    (daemon, client, bytes)
}

/// Sends `count` `state` requests in one write on a new connection (from a thread: the write
/// blocks once the daemon stops reading), and gives the connection.
fn state_burst(daemon: &Daemon, count: usize) -> (TcpStream, std::thread::JoinHandle<()>) {
    let stream = TcpStream::connect(&daemon.address).unwrap();
    let mut writer = stream.try_clone().unwrap();
    let writing = std::thread::spawn(move || {
        let _ = writer.write_all("{\"type\":\"state\"}\n".repeat(count).as_bytes());
    });
    (stream, writing)
}

const QUEUE_BOUND: usize = 16 << 20;

#[test]
fn replies_past_a_clients_queue_bound_are_answered_with_errors_until_it_reads() {
    // 5,000 `state` requests more than 16 MiB of replies, in one write, from a client that
    // reads only after a second: the daemon used to queue a reply for each (4,096 of them at
    // most, without a byte bound: 3.1 GB on a 500-material project) or drop the client. Now
    // the replies past the bound are each answered with a short `error`, and nothing is lost.
    let project = watched_project();
    let (daemon, _subscriber, reply_bytes) = daemon_and_state_size(&project);
    let requests = QUEUE_BOUND / reply_bytes + 5000;
    let (stream, writing) = state_burst(&daemon, requests);
    std::thread::sleep(Duration::from_secs(1));
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let mut reader = BufReader::new(stream);
    let (mut states, mut refusals, mut line) = (0usize, 0usize, String::new());
    let mut first_refusal = String::new();
    while states + refusals < requests {
        line.clear();
        let read = reader.read_line(&mut line).unwrap_or(0);
        assert!(read > 0, "disconnected after {states} replies and {refusals} refusals of {requests}");
        let message: Value = serde_json::from_str(&line).unwrap();
        match message["type"].as_str() {
            Some("state") => states += 1,
            Some("error") if refusals == 0 => {
                first_refusal = line.clone();
                refusals += 1;
            }
            Some("error") => refusals += 1,
            _ => {}
        }
    }
    let _ = writing.join();
    println!("{requests} state requests of {reply_bytes} bytes: {states} answered, {refusals} refused");
    assert!(refusals > 0, "replies past the bound are refused");
    assert!(first_refusal.contains("bytes are queued for this client already (at most 16777216)"), "{first_refusal}");
    assert!(states * reply_bytes <= 2 * QUEUE_BOUND, "at most the bound and the sockets' buffers: {states}");
}

#[test]
fn a_client_that_never_reads_its_replies_is_disconnected_and_the_daemon_stays_small() {
    let project = watched_project();
    let (daemon, mut subscriber, reply_bytes) = daemon_and_state_size(&project);
    let before = resident_mib(&daemon);
    let requests = 200_000;
    let (_stream, _writing) = state_burst(&daemon, requests);
    let started = Instant::now();
    while !daemon.log.lock().unwrap().contains("asks without reading") {
        assert!(started.elapsed() < Duration::from_secs(30), "{}", daemon.log.lock().unwrap());
        std::thread::sleep(Duration::from_millis(100));
    }
    let after = resident_mib(&daemon);
    println!("{requests} state requests of {reply_bytes} bytes never read: daemon {before} → {after} MiB");
    assert!(after <= before + 48, "the daemon grew from {before} to {after} MiB");
    // The daemon and its subscriber are unharmed.
    subscriber.send(r#"{"type":"ping"}"#);
    assert_eq!(subscriber.receive()["type"], "pong");
}

#[test]
fn a_handshake_sent_a_byte_a_second_is_closed_five_seconds_after_it_connected() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut stream = TcpStream::connect(&daemon.address).unwrap();
    let request = format!(
        "GET / HTTP/1.1\r\nHost: {}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: \
         dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
        daemon.address
    );
    let started = Instant::now();
    let mut closed_after = None;
    for byte in request.bytes().take(12) {
        if stream.write_all(&[byte]).is_err() {
            closed_after = Some(started.elapsed());
            break;
        }
        stream.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
        match stream.read(&mut [0u8; 64]) {
            Ok(0) => {
                closed_after = Some(started.elapsed());
                break;
            }
            Ok(_) => panic!("the daemon answered half a request"),
            Err(error) if matches!(error.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => {
                closed_after = Some(started.elapsed());
                break;
            }
        }
    }
    let closed_after = closed_after.expect("a handshake trickling in for 12 s is closed");
    assert!(closed_after < Duration::from_millis(7000), "closed after {closed_after:?}");
}

#[test]
fn connections_stalled_in_their_handshake_give_way_to_a_browser() {
    // 64 connections that open a handshake and stall (reopened as they are closed) used to hold
    // every opening slot: a new one was closed at once. The oldest stalled one that has been
    // opening over a second now gives way.
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let stalled: Vec<TcpStream> = (0..64)
        .map(|_| {
            let mut stream = TcpStream::connect(&daemon.address).unwrap();
            stream.write_all(b"G").unwrap();
            stream
        })
        .collect();
    std::thread::sleep(Duration::from_millis(1500));
    let mut socket = websocket(&daemon, Some("http://127.0.0.1:8080")).expect("a browser's handshake");
    assert_eq!(next_message(&mut socket).unwrap()["type"], "hello");
    drop(stalled);
}

#[test]
fn pages_from_other_sites_are_refused_unless_allowed_and_loopback_pages_and_tools_are_served() {
    let project = watched_project();
    let daemon =
        Daemon::start_with(&project, &["--listen", "127.0.0.1:0", "--allow-origin", "https://editor.example:8443"]);
    assert_eq!(websocket(&daemon, Some("https://evil.example")).err(), Some(403), "a page on another site");
    assert_eq!(websocket(&daemon, Some("null")).err(), Some(403), "a sandboxed page or a file");
    assert_eq!(websocket(&daemon, Some("http://localhost.evil.example")).err(), Some(403));
    for origin in [None, Some("http://127.0.0.1:8080"), Some("http://localhost:3000"), Some("http://[::1]:8080")]
        .into_iter()
        .chain([Some("https://editor.example:8443")])
    {
        let mut socket = websocket(&daemon, origin).unwrap_or_else(|status| panic!("{origin:?} refused ({status})"));
        assert_eq!(next_message(&mut socket).unwrap()["type"], "hello", "{origin:?}");
    }
    let started = Instant::now();
    while !daemon.log.lock().unwrap().contains("refused a WebSocket from the page at https://evil.example") {
        assert!(started.elapsed() < Duration::from_secs(10), "the refusal is logged");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_subscribed_page_that_answers_no_ping_is_closed_and_one_that_does_stays() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut silent = websocket(&daemon, None).unwrap();
    let mut alive = websocket(&daemon, None).unwrap();
    for socket in [&mut silent, &mut alive] {
        socket.send(Message::text(r#"{"type":"subscribe","since":0}"#)).unwrap();
    }
    // `alive` reads, so tungstenite answers the daemon's pings; `silent` reads nothing for 20 s.
    let deadline = Instant::now() + Duration::from_secs(20);
    alive.get_mut().set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    while Instant::now() < deadline {
        match alive.read() {
            Ok(Message::Close(frame)) => panic!("a page that answers pings was closed: {frame:?}"),
            Ok(_) => {}
            Err(tungstenite::Error::Io(error))
                if matches!(error.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(error) => panic!("{error}"),
        }
        let _ = alive.flush();
    }
    // Read raw (tungstenite would answer the queued pings first and meet the closed socket).
    let mut raw = Vec::new();
    let _ = silent.get_mut().read_to_end(&mut raw);
    let frames = server_frames(&raw);
    assert!(frames.iter().filter(|(opcode, _)| *opcode == 0x9).count() >= 2, "pinged first: {frames:?}");
    let close = frames.iter().find(|(opcode, _)| *opcode == 0x8).expect("a close frame");
    assert_eq!(close.1[..2], 1001u16.to_be_bytes(), "closed as going away (1001): {close:?}");
    alive.get_mut().set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    alive.send(Message::text(r#"{"type":"ping"}"#)).unwrap();
    let pong = loop {
        let message = next_message(&mut alive).expect("still connected");
        if message["type"] == "pong" {
            break message;
        }
    };
    assert!(pong["revision"].is_u64());
}

/// The frames of an unmasked (server) WebSocket byte stream: opcode and payload.
fn server_frames(mut bytes: &[u8]) -> Vec<(u8, Vec<u8>)> {
    let mut frames = Vec::new();
    while bytes.len() >= 2 {
        let (opcode, length) = (bytes[0] & 0x0f, (bytes[1] & 0x7f) as usize);
        let (length, header) = match length {
            126 if bytes.len() >= 4 => (u16::from_be_bytes([bytes[2], bytes[3]]) as usize, 4),
            127 if bytes.len() >= 10 => (u64::from_be_bytes(bytes[2..10].try_into().unwrap()) as usize, 10),
            126 | 127 => break,
            length => (length, 2),
        };
        let Some(payload) = bytes.get(header..header + length) else { break };
        frames.push((opcode, payload.to_vec()));
        bytes = &bytes[header + length..];
    }
    frames
}

#[test]
fn clients_that_only_ping_give_their_slots_to_an_engine() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    // 64 clients that never subscribe but ping every second (they used to be never idle).
    let pingers: Vec<_> = (0..64)
        .map(|_| {
            let stop = stop.clone();
            let mut stream = TcpStream::connect(&daemon.address).unwrap();
            std::thread::spawn(move || {
                let mut reader = BufReader::new(stream.try_clone().unwrap());
                stream.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    if stream.write_all(b"{\"type\":\"ping\"}\n").is_err() {
                        return;
                    }
                    let mut line = String::new();
                    if matches!(reader.read_line(&mut line), Ok(0)) {
                        return;
                    }
                    std::thread::sleep(Duration::from_millis(1000));
                }
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(6000));
    let mut engine = daemon.connect();
    engine.subscribe(Some(0));
    let batch = engine.batch();
    assert!(batch["revision"].as_u64().unwrap() >= 1, "{batch}");
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    for pinger in pingers {
        let _ = pinger.join();
    }
}

#[test]
fn websocket_messages_over_the_limit_are_answered_once_and_bad_ones_get_a_close_frame() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut socket = websocket(&daemon, None).unwrap();
    assert_eq!(next_message(&mut socket).unwrap()["type"], "hello");
    // 70 KB and 140 KB: one error each, and the connection stays (as on JSON lines).
    for size in [70_000, 140_000] {
        socket.send(Message::text(format!("{{\"type\":\"ping\",\"pad\":\"{}\"}}", "x".repeat(size)))).unwrap();
        socket.send(Message::text(r#"{"type":"ping"}"#)).unwrap();
        let error = next_message(&mut socket).unwrap();
        assert_eq!(error["type"], "error", "{error}");
        assert!(error["message"].as_str().unwrap().contains("longer than 65536 bytes"), "{error}");
        let pong = next_message(&mut socket).unwrap();
        assert_eq!(pong["type"], "pong", "one error per message, then the next request: {pong}");
    }
    // A text frame that is not UTF-8 closes the connection with 1007, and says so.
    socket.write(Message::Frame(Frame::message(vec![b'{', 0xff, 0xfe, b'}'], OpCode::Data(Data::Text), true))).unwrap();
    socket.flush().unwrap();
    assert_eq!(next_message(&mut socket).err(), Some(Some(CloseCode::Invalid)));
    // Over a MiB: closed with 1009 (the rest of such a frame cannot be skipped).
    let mut socket = websocket(&daemon, None).unwrap();
    next_message(&mut socket).unwrap();
    // (The daemon may close before the whole message is written: the write's error is no matter.)
    let _ = socket.send(Message::text("x".repeat(2 << 20)));
    assert_eq!(next_message(&mut socket).err(), Some(Some(CloseCode::Size)));
}
