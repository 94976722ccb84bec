//! The hot-reload server (an IO edge): newline-delimited JSON over TCP, and the same messages
//! over a WebSocket on the same port (a connection that opens with an HTTP request), many
//! clients at once, `since` replay, and the graph request. The protocol is documented in
//! `PROTOCOL.md`.
//!
//! Every client has a reader thread (bounded lines; malformed input is answered with an `error`
//! message and never reaches the daemon) and a writer thread fed by a bounded queue, so a slow
//! or vanished client never blocks the daemon: when its queue is full it is disconnected.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use crate::graph::{Graph, GraphFormat};
use crate::summary::ChangedArtifact;

/// 2: `hello` names the output folder; `building` when a batch starts; `ping` / `pong`; `state`.
pub(crate) const PROTOCOL_VERSION: u32 = 2;

/// Limits of the server.
#[derive(Clone, Debug)]
pub(crate) struct ServerSettings {
    /// Longest client line accepted, in bytes; longer lines are answered with an error.
    pub max_line_bytes: usize,
    /// How many batches are kept for `since` replay.
    pub history: usize,
    /// Messages queued for one client before it is disconnected as too slow.
    pub client_queue: usize,
    /// Clients connected at once; more are answered with an error and closed, unless one of
    /// them is idle (see `idle_grace`).
    pub max_clients: usize,
    /// A client that has neither subscribed nor sent a request for this long is idle: when every
    /// slot is taken, a new client takes the slot of the longest idle one, so that idle
    /// connections cannot lock everyone out.
    pub idle_grace: std::time::Duration,
}

impl Default for ServerSettings {
    fn default() -> Self {
        ServerSettings {
            max_line_bytes: 64 * 1024,
            history: 1024,
            client_queue: 4096,
            max_clients: 64,
            idle_grace: std::time::Duration::from_secs(5),
        }
    }
}

/// One finished build, as the engine sees it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct BatchEvent {
    pub revision: u64,
    /// Artifacts renamed into place by this build, with their blake3 hashes.
    pub changed: Vec<ChangedArtifact>,
    /// Artifacts deleted by this build (project-relative paths).
    pub removed: Vec<String>,
    /// Every failed asset's problems.
    pub failed: Vec<FailedEntry>,
    /// Wall time of the build in milliseconds.
    pub ms: f64,
}

/// One problem of a failed asset (or of `pipeline.ron`, with `asset` null and stage `config`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct FailedEntry {
    pub asset: Option<String>,
    pub stage: String,
    pub message: String,
    pub file: String,
    pub line: Option<u32>,
    pub column: Option<u32>,
}

#[derive(Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
enum Outgoing<'a> {
    Hello { protocol: u32, revision: u64, output: String },
    Building { revision: u64, files: &'a [String] },
    Batch(&'a BatchEvent),
    Pong { revision: u64 },
    State { revision: u64, artifacts: Vec<&'a ChangedArtifact> },
    Resync { revision: u64, message: String },
    Graph { format: &'static str, graph: Option<&'a Graph>, text: Option<String> },
    Error { message: String },
}

/// A client's request line, parsed.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Request {
    Ping,
    State,
    Subscribe {
        #[serde(default)]
        since: Option<u64>,
    },
    Graph {
        #[serde(default)]
        format: Option<String>,
        #[serde(default)]
        asset: Option<String>,
    },
}

/// Parses one client line (without its `\n`): `Ok(None)` for a blank line, an error message
/// for anything that is not a request. JSON nesting is bounded by `serde_json` (128 levels).
pub fn parse_request(bytes: &[u8]) -> Result<Option<Request>, String> {
    let text = String::from_utf8_lossy(bytes);
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    serde_json::from_str::<Request>(text).map(Some).map_err(|error| format!("malformed request: {error}"))
}

fn line(message: &Outgoing) -> Arc<str> {
    let mut text = serde_json::to_string(message).expect("messages serialise");
    text.push('\n');
    text.into()
}

struct Client {
    id: u64,
    queue: SyncSender<Arc<str>>,
    stream: TcpStream,
    subscribed: bool,
    /// When it connected or last sent a request.
    last_request: std::time::Instant,
}

struct State {
    revision: u64,
    /// The project's output folder (project-relative, `/`-separated), as `hello` names it.
    output: String,
    /// Every artifact in the output folder by path, as `state` answers: the manifest when the
    /// daemon started, then every published batch's changes.
    artifacts: std::collections::BTreeMap<String, ChangedArtifact>,
    /// Recent batches: (revision, the line sent).
    history: VecDeque<(u64, Arc<str>)>,
    clients: Vec<Client>,
    /// The graph of the revision it names, until a batch makes it stale.
    graph: Option<(u64, Arc<Graph>)>,
    next_client: u64,
}

/// Asks the daemon for the current graph and its revision (the daemon's owner thread computes
/// it between batches, only when a client asks).
pub(crate) type GraphSource = Arc<dyn Fn() -> Option<(u64, Graph)> + Send + Sync>;

/// A running server; dropping it does not stop the listener thread (it lives as long as the
/// daemon process).
#[derive(Clone)]
pub(crate) struct Server {
    state: Arc<Mutex<State>>,
    settings: ServerSettings,
    address: SocketAddr,
    graph_source: Arc<Mutex<Option<GraphSource>>>,
    /// Connections not yet given a slot (being told apart, or in a WebSocket handshake).
    pending: Arc<std::sync::atomic::AtomicUsize>,
}

#[derive(Debug, thiserror::Error)]
#[error("cannot listen on {address}: {source}")]
pub struct ServerError {
    pub address: SocketAddr,
    pub source: std::io::Error,
}

impl Server {
    /// Binds `address` and starts accepting clients on a thread of its own.
    pub fn start(
        address: SocketAddr,
        settings: ServerSettings,
        revision: u64,
        output: &std::path::Path,
        manifest: &crate::artifacts::Manifest,
    ) -> Result<Server, ServerError> {
        let listener = TcpListener::bind(address).map_err(|source| ServerError { address, source })?;
        let address = listener.local_addr().map_err(|source| ServerError { address, source })?;
        let artifacts = manifest_artifacts(output, manifest);
        let output = crate::diagnostic::display_path(output);
        let state = State {
            revision,
            output,
            artifacts,
            history: VecDeque::new(),
            clients: Vec::new(),
            graph: None,
            next_client: 0,
        };
        let server = Server {
            state: Arc::new(Mutex::new(state)),
            settings,
            address,
            graph_source: Arc::new(Mutex::new(None)),
            pending: Arc::default(),
        };
        let accepting = server.clone();
        std::thread::Builder::new()
            .name("cirrus-accept".into())
            .spawn(move || {
                for stream in listener.incoming() {
                    match stream {
                        Ok(stream) => accepting.accept(stream),
                        Err(error) => tracing::warn!("hot-reload server: accept failed: {error}"),
                    }
                }
            })
            .expect("spawn the accept thread");
        Ok(server)
    }

    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Sends a finished batch to every subscribed client and keeps it for replay.
    pub(crate) fn publish(&self, batch: &BatchEvent) {
        let message = line(&Outgoing::Batch(batch));
        let mut state = self.state.lock().expect("server state");
        state.revision = batch.revision;
        for removed in &batch.removed {
            state.artifacts.remove(removed);
        }
        for changed in &batch.changed {
            state.artifacts.insert(changed.path.clone(), changed.clone());
        }
        state.history.push_back((batch.revision, message.clone()));
        while state.history.len() > self.settings.history {
            state.history.pop_front();
        }
        state.clients.retain(|client| !client.subscribed || send(client, message.clone()));
    }

    /// Tells every subscribed client that a build of the edits to `files` (project-relative)
    /// started; not kept for replay.
    pub(crate) fn building(&self, files: &[String]) {
        let mut state = self.state.lock().expect("server state");
        let message = line(&Outgoing::Building { revision: state.revision, files });
        state.clients.retain(|client| !client.subscribed || send(client, message.clone()));
    }

    /// The output folder that `hello` names from now on (the pipeline file named another), and
    /// the artifacts its manifest lists.
    pub(crate) fn set_output(&self, output: &std::path::Path, manifest: &crate::artifacts::Manifest) {
        let mut state = self.state.lock().expect("server state");
        state.output = crate::diagnostic::display_path(output);
        state.artifacts = manifest_artifacts(output, manifest);
    }

    /// Where `graph` requests get the graph when the last one is stale.
    pub(crate) fn set_graph_source(&self, source: GraphSource) {
        *self.graph_source.lock().expect("graph source") = Some(source);
    }

    /// The graph of the last published revision: kept, or asked of the graph source (without
    /// holding the state, which the daemon needs to publish meanwhile).
    fn current_graph(&self) -> Arc<Graph> {
        {
            let state = self.state.lock().expect("server state");
            if let Some((revision, graph)) = &state.graph {
                if *revision == state.revision {
                    return graph.clone();
                }
            }
        }
        let source = self.graph_source.lock().expect("graph source").clone();
        let Some((revision, graph)) = source.and_then(|source| source()) else { return Arc::default() };
        let graph = Arc::new(graph);
        let mut state = self.state.lock().expect("server state");
        if revision == state.revision {
            state.graph = Some((revision, graph.clone()));
        }
        graph
    }

    /// Serves a new connection on a thread of its own (the accept loop never waits on a client);
    /// closes it at once when `max_clients` others are still being told apart or shaking hands
    /// (each for at most `WEBSOCKET_HANDSHAKE`), so half-open connections cannot pile up threads.
    fn accept(&self, stream: TcpStream) {
        use std::sync::atomic::Ordering;
        if self.pending.fetch_add(1, Ordering::SeqCst) >= self.settings.max_clients {
            self.pending.fetch_sub(1, Ordering::SeqCst);
            let _ = stream.shutdown(Shutdown::Both);
            tracing::warn!(
                "hot-reload server: {} connections still opening: closed a new one",
                self.settings.max_clients
            );
            return;
        }
        let server = self.clone();
        let spawned = std::thread::Builder::new().name("cirrus-client".into()).spawn(move || server.serve(stream));
        if let Err(error) = spawned {
            self.pending.fetch_sub(1, Ordering::SeqCst);
            tracing::warn!("hot-reload server: cannot start a client thread: {error}");
        }
    }

    /// One connection: a WebSocket when it opens with an HTTP request (a browser's upgrade),
    /// else JSON lines.
    fn serve(&self, stream: TcpStream) {
        let _ = stream.set_nodelay(true);
        let opening = Opening { pending: &self.pending, open: std::cell::Cell::new(true) };
        if opens_with_http(&stream) {
            self.serve_websocket(stream, &opening);
        } else {
            self.serve_lines(stream, &opening);
        }
    }

    fn serve_lines(&self, stream: TcpStream, opening: &Opening) {
        let (Ok(reader_stream), Ok(writer_stream)) = (stream.try_clone(), stream.try_clone()) else { return };
        let registered = self.register(&stream);
        opening.finish();
        let (id, outgoing) = match registered {
            Ok(registered) => registered,
            Err(refusal) => {
                let mut stream = stream;
                let _ = stream.set_write_timeout(Some(std::time::Duration::from_millis(200)));
                let _ = stream.write_all(refusal.as_bytes());
                let _ = stream.shutdown(Shutdown::Both);
                return;
            }
        };
        let _ = std::thread::Builder::new()
            .name(format!("cirrus-client-{id}-write"))
            .spawn(move || write_loop(writer_stream, outgoing));
        self.read_loop(id, reader_stream);
        self.disconnect(id);
        tracing::info!("hot-reload client {id} disconnected");
    }

    /// The same messages over a WebSocket (RFC 6455, `tungstenite`): one JSON message per text
    /// frame each way. One thread reads (polling every `WEBSOCKET_POLL`) and sends what the
    /// client's queue holds.
    fn serve_websocket(&self, stream: TcpStream, opening: &Opening) {
        let limit = Some(self.settings.max_line_bytes);
        let config = tungstenite::protocol::WebSocketConfig::default().max_message_size(limit).max_frame_size(limit);
        let _ = stream.set_read_timeout(Some(WEBSOCKET_HANDSHAKE));
        let Ok(raw) = stream.try_clone() else { return };
        let mut socket = match tungstenite::accept_with_config(raw, Some(config)) {
            Ok(socket) => socket,
            Err(error) => {
                tracing::info!("hot-reload server: a WebSocket handshake failed: {error}");
                return;
            }
        };
        let registered = self.register(&stream);
        opening.finish();
        let (id, outgoing) = match registered {
            Ok(registered) => registered,
            Err(refusal) => {
                let _ = socket.send(tungstenite::Message::text(refusal.trim_end()));
                let _ = socket.close(None);
                let _ = socket.flush();
                return;
            }
        };
        let _ = stream.set_read_timeout(Some(WEBSOCKET_POLL));
        self.websocket_loop(id, &mut socket, &outgoing);
        self.disconnect(id);
        tracing::info!("hot-reload client {id} (WebSocket) disconnected");
    }

    fn websocket_loop(&self, id: u64, socket: &mut tungstenite::WebSocket<TcpStream>, outgoing: &Receiver<Arc<str>>) {
        use std::sync::mpsc::TryRecvError;
        use tungstenite::{Error, Message};
        loop {
            loop {
                match outgoing.try_recv() {
                    Ok(message) if socket.send(Message::text(message.trim_end())).is_err() => return,
                    Ok(_) => {}
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => return,
                }
            }
            match socket.read() {
                Ok(Message::Text(text)) if !self.handle_line(id, text.as_bytes()) => return,
                Ok(Message::Binary(_)) => self.reply(
                    id,
                    Outgoing::Error {
                        message: "binary messages are not part of the protocol: send JSON as text".into(),
                    },
                ),
                Ok(Message::Close(_)) => {
                    let _ = socket.flush();
                    return;
                }
                Ok(_) => {}
                Err(Error::Io(error))
                    if matches!(error.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
                Err(Error::Capacity(_)) => {
                    let message = format!("message longer than {} bytes", self.settings.max_line_bytes);
                    self.reply(id, Outgoing::Error { message });
                }
                Err(_) => return,
            }
        }
    }

    /// Takes a client slot for a new connection (the longest idle client gives up its own when
    /// every slot is taken) and queues `hello`: the client's id and queue, or the refusal to send
    /// it when no slot is free.
    fn register(&self, stream: &TcpStream) -> Result<(u64, Receiver<Arc<str>>), Arc<str>> {
        let Ok(stream) = stream.try_clone() else {
            return Err(line(&Outgoing::Error { message: "the connection failed".into() }));
        };
        let (queue, outgoing) = sync_channel::<Arc<str>>(self.settings.client_queue);
        let mut state = self.state.lock().expect("server state");
        if state.clients.len() >= self.settings.max_clients {
            // The longest idle client (never subscribed, silent past the grace) makes room.
            let idle = state
                .clients
                .iter()
                .enumerate()
                .filter(|(_, client)| !client.subscribed && client.last_request.elapsed() >= self.settings.idle_grace)
                .min_by_key(|(_, client)| client.last_request)
                .map(|(position, _)| position);
            if let Some(position) = idle {
                let client = state.clients.remove(position);
                let notice = line(&Outgoing::Error {
                    message: format!(
                        "idle for {:.0} s while every slot was taken: disconnected",
                        client.last_request.elapsed().as_secs_f64()
                    ),
                });
                let _ = client.queue.try_send(notice);
                let _ = client.stream.shutdown(Shutdown::Read);
                tracing::info!("hot-reload client {} was idle: its slot went to a new client", client.id);
            }
        }
        if state.clients.len() >= self.settings.max_clients {
            tracing::warn!("hot-reload server: refused a client, {} connected already", state.clients.len());
            return Err(line(&Outgoing::Error {
                message: format!("too many clients ({} connected): try again later", state.clients.len()),
            }));
        }
        let id = state.next_client;
        state.next_client += 1;
        let hello = line(&Outgoing::Hello {
            protocol: PROTOCOL_VERSION,
            revision: state.revision,
            output: state.output.clone(),
        });
        let peer = stream.peer_addr().map(|address| address.to_string()).unwrap_or_default();
        let client = Client { id, queue, stream, subscribed: false, last_request: std::time::Instant::now() };
        if !send(&client, hello) {
            return Err(line(&Outgoing::Error { message: "could not queue the greeting".into() }));
        }
        state.clients.push(client);
        tracing::info!("hot-reload client {id} connected from {peer}");
        Ok((id, outgoing))
    }

    /// Notes a request from client `id`; false when it is no longer connected.
    fn touch(&self, id: u64) -> bool {
        let mut state = self.state.lock().expect("server state");
        let client = state.clients.iter_mut().find(|client| client.id == id);
        client.map(|client| client.last_request = std::time::Instant::now()).is_some()
    }

    fn disconnect(&self, id: u64) {
        let mut state = self.state.lock().expect("server state");
        if let Some(position) = state.clients.iter().position(|client| client.id == id) {
            let client = state.clients.remove(position);
            let _ = client.stream.shutdown(Shutdown::Both);
        }
    }

    fn read_loop(&self, id: u64, stream: TcpStream) {
        let mut reader = BufReader::new(stream);
        loop {
            match read_bounded_line(&mut reader, self.settings.max_line_bytes) {
                ClientLine::End => return,
                ClientLine::TooLong => self.reply(
                    id,
                    Outgoing::Error { message: format!("line longer than {} bytes", self.settings.max_line_bytes) },
                ),
                ClientLine::Line(bytes) if !self.handle_line(id, &bytes) => return,
                ClientLine::Line(_) => {}
            }
        }
    }

    /// One message from client `id`: a request handled, or an error answered; false when the
    /// client no longer holds a slot (it went to another while this one was idle).
    fn handle_line(&self, id: u64, bytes: &[u8]) -> bool {
        if !self.touch(id) {
            return false;
        }
        match parse_request(bytes) {
            Ok(Some(request)) => self.handle(id, request),
            Ok(None) => {}
            Err(message) => self.reply(id, Outgoing::Error { message }),
        }
        true
    }

    fn handle(&self, id: u64, request: Request) {
        match request {
            Request::Ping => {
                let revision = self.state.lock().expect("server state").revision;
                self.reply(id, Outgoing::Pong { revision });
            }
            Request::State => {
                let mut state = self.state.lock().expect("server state");
                let message =
                    line(&Outgoing::State { revision: state.revision, artifacts: state.artifacts.values().collect() });
                state.clients.retain(|client| client.id != id || send(client, message.clone()));
            }
            Request::Subscribe { since } => {
                let mut state = self.state.lock().expect("server state");
                let revision = state.revision;
                let oldest = state.history.front().map(|(revision, _)| *revision);
                let mut replay: Vec<Arc<str>> = Vec::new();
                if let Some(since) = since {
                    if since > revision {
                        replay.push(line(&Outgoing::Resync {
                            revision,
                            message: format!(
                                "revision {since} is newer than the daemon's revision {revision} (the output was \
                                    baked by another \
                                 daemon or cleaned): reload every artifact"
                            ),
                        }));
                    } else if oldest.is_some_and(|oldest| since + 1 < oldest) || (oldest.is_none() && since < revision)
                    {
                        replay.push(line(&Outgoing::Resync {
                            revision,
                            message: format!(
                                "revision {since} is older than the daemon's history: reload every artifact"
                            ),
                        }));
                    }
                    replay
                        .extend(state.history.iter().filter(|(batch, _)| *batch > since).map(|(_, line)| line.clone()));
                }
                let Some(client) = state.clients.iter_mut().find(|client| client.id == id) else { return };
                client.subscribed = true;
                let client = &*client;
                let delivered = replay.into_iter().all(|message| send(client, message));
                if !delivered {
                    state.clients.retain(|client| client.id != id);
                }
            }
            Request::Graph { format, asset } => {
                let name = format.as_deref().unwrap_or("json");
                let Some(format) = GraphFormat::ALL.into_iter().find(|format| format.name() == name) else {
                    return self.reply(
                        id,
                        Outgoing::Error { message: format!("unknown graph format `{name}`: json, dot or mermaid") },
                    );
                };
                let graph = self.current_graph();
                let graph = match &asset {
                    Some(asset) if !graph.has_asset(asset) => {
                        return self
                            .reply(id, Outgoing::Error { message: format!("no asset named `{asset}` in the graph") });
                    }
                    Some(asset) => Arc::new(graph.for_asset(asset)),
                    None => graph,
                };
                let message = match format {
                    GraphFormat::Json => Outgoing::Graph { format: "json", graph: Some(&graph), text: None },
                    GraphFormat::Dot => {
                        Outgoing::Graph { format: "dot", graph: None, text: Some(graph.render(format)) }
                    }
                    GraphFormat::Mermaid => {
                        Outgoing::Graph { format: "mermaid", graph: None, text: Some(graph.render(format)) }
                    }
                };
                self.reply(id, message);
            }
        }
    }

    fn reply(&self, id: u64, message: Outgoing) {
        let message = line(&message);
        let mut state = self.state.lock().expect("server state");
        state.clients.retain(|client| client.id != id || send(client, message.clone()));
    }
}

/// The artifacts `manifest` lists, by path, as `state` and `batch` name them (`output`: the
/// project-relative output folder).
fn manifest_artifacts(
    output: &std::path::Path,
    manifest: &crate::artifacts::Manifest,
) -> std::collections::BTreeMap<String, ChangedArtifact> {
    manifest
        .artifacts
        .iter()
        .map(|(path, entry)| {
            let folder = format!("{}/", crate::diagnostic::display_path(&output.join(&entry.asset)));
            let artifact = ChangedArtifact {
                role: entry.role,
                asset: entry.asset.clone(),
                artifact: path.strip_prefix(&folder).unwrap_or(path).to_string(),
                path: path.clone(),
                hash: entry.hash.clone(),
                meaning: entry.meaning.clone(),
            };
            (path.clone(), artifact)
        })
        .collect()
}

/// Queues `message` for `client`; false (and the connection closed) when its queue is full.
fn send(client: &Client, message: Arc<str>) -> bool {
    match client.queue.try_send(message) {
        Ok(()) => true,
        Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
            tracing::warn!("hot-reload client {} is not reading: disconnected", client.id);
            let _ = client.stream.shutdown(Shutdown::Both);
            false
        }
    }
}

/// A connection still opening, counted in `Server::pending` until it is given a slot or closed.
struct Opening<'a> {
    pending: &'a std::sync::atomic::AtomicUsize,
    open: std::cell::Cell<bool>,
}

impl Opening<'_> {
    fn finish(&self) {
        if self.open.replace(false) {
            self.pending.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
        }
    }
}

impl Drop for Opening<'_> {
    fn drop(&mut self) {
        self.finish();
    }
}

/// How long a new connection may stay silent before it is taken for a JSON-lines client (a
/// WebSocket client opens with its HTTP request at once; a JSON-lines client that waits for
/// `hello` gets it this much later).
const SNIFF_WINDOW: std::time::Duration = std::time::Duration::from_millis(150);
/// How long a WebSocket handshake may take.
const WEBSOCKET_HANDSHAKE: std::time::Duration = std::time::Duration::from_secs(5);
/// How often a WebSocket client's thread looks at its queue between reads.
const WEBSOCKET_POLL: std::time::Duration = std::time::Duration::from_millis(10);

/// Whether a connection's first bytes, within `SNIFF_WINDOW`, are an HTTP request (`G` of
/// `GET`: no JSON message starts with it).
fn opens_with_http(stream: &TcpStream) -> bool {
    let _ = stream.set_read_timeout(Some(SNIFF_WINDOW));
    let mut first = [0u8; 1];
    let http = matches!(stream.peek(&mut first), Ok(1) if first[0] == b'G');
    let _ = stream.set_read_timeout(None);
    http
}

fn write_loop(mut stream: TcpStream, outgoing: Receiver<Arc<str>>) {
    for message in outgoing {
        if stream.write_all(message.as_bytes()).is_err() {
            let _ = stream.shutdown(Shutdown::Both);
            return;
        }
    }
}

enum ClientLine {
    Line(Vec<u8>),
    TooLong,
    End,
}

/// Reads one `\n`-terminated line of at most `limit` bytes; a longer line is skipped to its end.
/// A line cut off by the end of the stream is dropped (a half-sent request does nothing).
fn read_bounded_line(reader: &mut impl BufRead, limit: usize) -> ClientLine {
    let mut line = Vec::new();
    let mut too_long = false;
    loop {
        let available = match reader.fill_buf() {
            Ok([]) | Err(_) => return ClientLine::End,
            Ok(available) => available,
        };
        let (chunk, found_end) = match available.iter().position(|&byte| byte == b'\n') {
            Some(end) => (&available[..end], true),
            None => (available, false),
        };
        if !too_long {
            if line.len() + chunk.len() > limit {
                too_long = true;
                line = Vec::new();
            } else {
                line.extend_from_slice(chunk);
            }
        }
        let consumed = chunk.len() + usize::from(found_end);
        reader.consume(consumed);
        if found_end {
            return if too_long { ClientLine::TooLong } else { ClientLine::Line(line) };
        }
    }
}
