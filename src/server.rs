//! The hot-reload server (an IO edge): newline-delimited JSON over TCP, and the same messages
//! over a WebSocket on the same port (a connection that opens with an HTTP request), many
//! clients at once, `since` replay, and the graph request. The protocol is documented in
//! `docs/PROTOCOL.md`.
//!
//! Every client has a reader thread (bounded lines; malformed input is answered with an `error`
//! message and never reaches the daemon) and a writer thread fed by a queue bounded in bytes
//! (`Outbox`), so a slow or vanished client never blocks the daemon nor grows it: a
//! reply that would pass the bound is answered with an `error`, and a client whose batches no
//! longer fit, or whose errors no longer fit either, is disconnected. A WebSocket comes from a
//! page `origins` allows.

mod origins;
mod outbox;

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use self::origins::check_origin;
use self::outbox::Outbox;
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
    /// Bytes queued for one client, at most (a single message larger than this is queued only
    /// when nothing else is): a reply that would pass it is answered with an `error` instead, and
    /// a batch that would pass it disconnects the client (it can reconnect with `since`).
    pub client_queue_bytes: usize,
    /// Clients connected at once; more are answered with an error and closed, unless one of
    /// them may give way (see `idle_grace`).
    pub max_clients: usize,
    /// A client that has not subscribed and connected this long ago may give way: when every
    /// slot is taken, a new client takes the slot of the one connected longest, so that
    /// connections that only ping or say nothing cannot lock an engine out.
    pub idle_grace: Duration,
    /// Browser pages (WebSocket `Origin`s) allowed besides loopback ones (`http://127.0.0.1:8080`,
    /// `http://localhost:…`, `http://[::1]:…`); a request without an `Origin` (not a browser) is
    /// always allowed.
    pub allowed_origins: Vec<String>,
}

impl Default for ServerSettings {
    fn default() -> Self {
        ServerSettings {
            max_line_bytes: 64 * 1024,
            history: 1024,
            client_queue_bytes: 16 << 20,
            max_clients: 64,
            idle_grace: Duration::from_secs(5),
            allowed_origins: Vec::new(),
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
    outbox: Arc<Outbox>,
    stream: TcpStream,
    subscribed: bool,
    /// When it connected.
    connected: Instant,
}

impl Drop for Client {
    /// A client leaving the list closes its queue: its writer sends what is queued and stops.
    fn drop(&mut self) {
        self.outbox.close();
    }
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
    openings: Arc<Openings>,
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
            openings: Arc::default(),
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
        state.clients.retain(|client| !client.subscribed || self.send(client, message.clone()));
    }

    /// Tells every subscribed client that a build of the edits to `files` (project-relative)
    /// started; not kept for replay.
    pub(crate) fn building(&self, files: &[String]) {
        let mut state = self.state.lock().expect("server state");
        let message = line(&Outgoing::Building { revision: state.revision, files });
        state.clients.retain(|client| !client.subscribed || self.send(client, message.clone()));
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

    /// Serves a new connection on a thread of its own (the accept loop never waits on a client).
    /// At most `max_clients` connections may be opening at once (being told apart, or shaking
    /// hands, each for at most `WEBSOCKET_HANDSHAKE` from its connection): with all of them
    /// taken, the oldest one opening for longer than `OPENING_GRACE` is closed to make room (a
    /// browser's handshake takes milliseconds), else the new one is closed, so half-open
    /// connections can neither pile up threads nor lock engines out.
    fn accept(&self, stream: TcpStream) {
        let Some(opening) = self.openings.enter(&stream, self.settings.max_clients) else {
            let _ = stream.shutdown(Shutdown::Both);
            tracing::warn!(
                "hot-reload server: {} connections still opening: closed a new one",
                self.settings.max_clients
            );
            return;
        };
        let server = self.clone();
        let openings = self.openings.clone();
        let spawned = std::thread::Builder::new()
            .name("cirrus-client".into())
            .spawn(move || server.serve(stream, &Opening { openings: &openings, id: opening }));
        if let Err(error) = spawned {
            self.openings.leave(opening);
            tracing::warn!("hot-reload server: cannot start a client thread: {error}");
        }
    }

    /// One connection: a WebSocket when it opens with an HTTP request (a browser's upgrade),
    /// else JSON lines.
    fn serve(&self, stream: TcpStream, opening: &Opening) {
        let _ = stream.set_nodelay(true);
        if opens_with_http(&stream) {
            self.serve_websocket(stream, opening);
        } else {
            self.serve_lines(stream, opening);
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
            .spawn(move || write_loop(writer_stream, &outgoing));
        self.read_loop(id, reader_stream);
        self.disconnect(id);
        tracing::info!("hot-reload client {id} disconnected");
    }

    /// The same messages over a WebSocket (RFC 6455, `tungstenite`): one JSON message per text
    /// frame each way. The handshake must finish within `WEBSOCKET_HANDSHAKE` of the connection
    /// (however slowly its bytes come), from a page `origin_allowed` accepts. Then one thread
    /// reads (polling every `WEBSOCKET_POLL`) and sends what the client's queue holds.
    fn serve_websocket(&self, stream: TcpStream, opening: &Opening) {
        // Frames up to `WEBSOCKET_MAX_MESSAGE` are read and, when over `max_line_bytes`, answered
        // with an error; a larger one closes the connection (1009), since its rest cannot be skipped.
        let limit = Some(WEBSOCKET_MAX_MESSAGE.max(self.settings.max_line_bytes));
        let config = tungstenite::protocol::WebSocketConfig::default().max_message_size(limit).max_frame_size(limit);
        let Ok(raw) = stream.try_clone() else { return };
        let _ = stream.set_write_timeout(Some(WEBSOCKET_HANDSHAKE));
        let raw = DeadlineStream { stream: raw, deadline: Some(Instant::now() + WEBSOCKET_HANDSHAKE) };
        let origins = &self.settings.allowed_origins;
        #[allow(clippy::result_large_err)] // tungstenite's error response type, not ours to box
        let check_origin = |request: &_, response| check_origin(request, response, origins);
        let mut socket = match tungstenite::accept_hdr_with_config(raw, check_origin, Some(config)) {
            Ok(socket) => socket,
            Err(error) => {
                tracing::info!("hot-reload server: a WebSocket handshake failed: {error}");
                return;
            }
        };
        socket.get_mut().deadline = None;
        let _ = stream.set_write_timeout(None);
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

    /// Serves a WebSocket client until it leaves: its queue sent, its messages handled, a ping
    /// sent after `WEBSOCKET_PING` of silence from it and the connection closed after
    /// `WEBSOCKET_SILENCE` (browsers answer pings by themselves), so a vanished page does not
    /// keep its slot.
    fn websocket_loop(&self, id: u64, socket: &mut tungstenite::WebSocket<DeadlineStream>, outgoing: &Outbox) {
        use tungstenite::protocol::frame::{coding::CloseCode, CloseFrame};
        use tungstenite::{error::CapacityError, Error, Message};
        let close = |socket: &mut tungstenite::WebSocket<DeadlineStream>, code: CloseCode, reason: String| {
            let _ = socket.close(Some(CloseFrame { code, reason: reason.into() }));
            let _ = socket.flush();
            drain_before_closing(&socket.get_ref().stream);
        };
        let (mut heard, mut pinged) = (Instant::now(), Instant::now());
        loop {
            loop {
                match outgoing.try_pop() {
                    Ok(Some(message)) if socket.send(Message::text(message.trim_end())).is_err() => return,
                    Ok(Some(_)) => {}
                    Ok(None) => break,
                    Err(()) => return,
                }
            }
            let read = socket.read();
            if !matches!(&read, Err(Error::Io(error)) if is_timeout(error)) {
                heard = Instant::now();
            }
            match read {
                Ok(Message::Text(text)) if text.len() > self.settings.max_line_bytes => {
                    let message = format!("message longer than {} bytes", self.settings.max_line_bytes);
                    self.reply(id, Outgoing::Error { message });
                }
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
                Err(Error::Io(error)) if is_timeout(&error) => {
                    if heard.elapsed() >= WEBSOCKET_SILENCE {
                        tracing::info!("hot-reload client {id} answered no ping for {WEBSOCKET_SILENCE:?}: closed");
                        let reason = format!("no answer to pings for {} s", WEBSOCKET_SILENCE.as_secs());
                        return close(socket, CloseCode::Away, reason);
                    }
                    if heard.elapsed() >= WEBSOCKET_PING && pinged.elapsed() >= WEBSOCKET_PING {
                        pinged = Instant::now();
                        if socket.send(Message::Ping(Default::default())).is_err() {
                            return;
                        }
                    }
                }
                Err(Error::Capacity(CapacityError::MessageTooLong { size, max_size })) => {
                    let reason = format!("a message of {size} bytes, over {max_size}");
                    return close(socket, CloseCode::Size, reason);
                }
                Err(Error::Utf8(_)) => return close(socket, CloseCode::Invalid, "a text frame not in UTF-8".into()),
                Err(Error::Protocol(error)) => return close(socket, CloseCode::Protocol, error.to_string()),
                Err(_) => return,
            }
        }
    }

    /// Takes a client slot for a new connection (when every slot is taken, the unsubscribed
    /// client connected longest, past `idle_grace`, gives up its own) and queues `hello`: the
    /// client's id and queue, or the refusal to send it when no slot is free.
    fn register(&self, stream: &TcpStream) -> Result<(u64, Arc<Outbox>), Arc<str>> {
        let Ok(stream) = stream.try_clone() else {
            return Err(line(&Outgoing::Error { message: "the connection failed".into() }));
        };
        let outbox = Arc::new(Outbox::new());
        let mut state = self.state.lock().expect("server state");
        if state.clients.len() >= self.settings.max_clients {
            // Subscribed clients are engines and keep their slots; of the others (idle, or only
            // pinging and asking), the one connected longest makes room.
            let idle = state
                .clients
                .iter()
                .enumerate()
                .filter(|(_, client)| !client.subscribed && client.connected.elapsed() >= self.settings.idle_grace)
                .min_by_key(|(_, client)| client.connected)
                .map(|(position, _)| position);
            if let Some(position) = idle {
                let client = state.clients.remove(position);
                let notice = line(&Outgoing::Error {
                    message: format!(
                        "connected {:.0} s without subscribing while every slot was taken: disconnected",
                        client.connected.elapsed().as_secs_f64()
                    ),
                });
                let _ = client.outbox.push(notice, usize::MAX);
                let _ = client.stream.shutdown(Shutdown::Read);
                tracing::info!("hot-reload client {} had not subscribed: its slot went to a new client", client.id);
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
        let client = Client { id, outbox: outbox.clone(), stream, subscribed: false, connected: Instant::now() };
        if !self.send(&client, hello) {
            return Err(line(&Outgoing::Error { message: "could not queue the greeting".into() }));
        }
        state.clients.push(client);
        tracing::info!("hot-reload client {id} connected from {peer}");
        Ok((id, outbox))
    }

    /// Whether client `id` still holds a slot.
    fn connected(&self, id: u64) -> bool {
        self.state.lock().expect("server state").clients.iter().any(|client| client.id == id)
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
        if !self.connected(id) {
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
                state.clients.retain(|client| client.id != id || self.send_reply(client, message.clone()));
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
                let delivered = replay.into_iter().all(|message| self.send(client, message));
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
        state.clients.retain(|client| client.id != id || self.send_reply(client, message.clone()));
    }

    /// Queues `message` (a batch, a replay, `hello`) for `client`; false (and the connection
    /// closed) when its queue cannot take it: a client that misses a batch must reconnect.
    fn send(&self, client: &Client, message: Arc<str>) -> bool {
        match client.outbox.push(message, self.settings.client_queue_bytes) {
            Ok(()) => true,
            Err(queued) => {
                tracing::warn!("hot-reload client {} is not reading ({queued} bytes queued): disconnected", client.id);
                let _ = client.stream.shutdown(Shutdown::Both);
                false
            }
        }
    }

    /// Queues a reply to one of `client`'s requests. A reply that would pass the queue's bound
    /// is answered with a short `error` instead (within `REFUSAL_RESERVE` over the bound); a
    /// client that stays over the bound, asking while it has read nothing for `CLIENT_STALL` or
    /// until even those errors no longer fit, is disconnected. False when it was.
    fn send_reply(&self, client: &Client, message: Arc<str>) -> bool {
        let bound = self.settings.client_queue_bytes;
        let Err(queued) = client.outbox.push(message.clone(), bound) else { return true };
        let (_, stalled) = client.outbox.backlog();
        let refusal = line(&Outgoing::Error {
            message: format!(
                "reply of {} bytes not sent: {queued} bytes are queued for this client already (at most {bound}); \
                 read them, then ask again",
                message.len()
            ),
        });
        if stalled < CLIENT_STALL && client.outbox.push(refusal, bound + REFUSAL_RESERVE).is_ok() {
            return true;
        }
        let (queued, stalled) = client.outbox.backlog();
        tracing::warn!(
            "hot-reload client {} asks without reading ({queued} bytes queued, none read for {:.1} s): disconnected",
            client.id,
            stalled.as_secs_f64()
        );
        let _ = client.stream.shutdown(Shutdown::Both);
        false
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

/// The connections still opening (not yet told apart, or in a WebSocket handshake), with when
/// each connected, so that the oldest can be closed to make room.
#[derive(Default)]
struct Openings {
    entries: Mutex<Vec<(u64, Instant, TcpStream)>>,
    next: std::sync::atomic::AtomicU64,
}

impl Openings {
    /// Counts `stream` as opening: its id, or `None` when `limit` are opening and none for longer
    /// than `OPENING_GRACE` (the oldest that is gives its place and is closed).
    fn enter(&self, stream: &TcpStream, limit: usize) -> Option<u64> {
        let mut entries = self.entries.lock().expect("openings");
        if entries.len() >= limit {
            let oldest = (0..entries.len()).min_by_key(|&position| entries[position].1)?;
            if entries[oldest].1.elapsed() < OPENING_GRACE {
                return None;
            }
            let (_, _, stalled) = entries.swap_remove(oldest);
            let _ = stalled.shutdown(Shutdown::Both);
            tracing::info!("hot-reload server: a connection opening for over {OPENING_GRACE:?} closed for a new one");
        }
        let id = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        entries.push((id, Instant::now(), stream.try_clone().ok()?));
        Some(id)
    }

    fn leave(&self, id: u64) {
        self.entries.lock().expect("openings").retain(|(entry, _, _)| *entry != id);
    }
}

/// A connection still opening, counted in `Server::openings` until it is given a slot or closed.
struct Opening<'a> {
    openings: &'a Openings,
    id: u64,
}

impl Opening<'_> {
    fn finish(&self) {
        self.openings.leave(self.id);
    }
}

impl Drop for Opening<'_> {
    fn drop(&mut self) {
        self.finish();
    }
}

/// A stream whose reads fail once its deadline passes, however slowly bytes arrive (a read
/// timeout alone restarts with every byte): the WebSocket handshake's.
struct DeadlineStream {
    stream: TcpStream,
    deadline: Option<Instant>,
}

impl Read for DeadlineStream {
    fn read(&mut self, buffer: &mut [u8]) -> std::io::Result<usize> {
        if let Some(deadline) = self.deadline {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, "the WebSocket handshake took too long"));
            }
            self.stream.set_read_timeout(Some(left))?;
        }
        self.stream.read(buffer)
    }
}

impl Write for DeadlineStream {
    fn write(&mut self, buffer: &[u8]) -> std::io::Result<usize> {
        self.stream.write(buffer)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.stream.flush()
    }
}

/// Reads and drops what a client still sends (the rest of a message too long to read) for at
/// most `CLOSE_DRAIN`, after the close frame went out and the writing half was shut: closing a
/// socket with unread bytes resets it, and the client would lose the close frame.
fn drain_before_closing(stream: &TcpStream) {
    let _ = stream.shutdown(Shutdown::Write);
    let deadline = Instant::now() + CLOSE_DRAIN;
    let mut buffer = [0u8; 64 * 1024];
    while let Some(left) = deadline.checked_duration_since(Instant::now()).filter(|left| !left.is_zero()) {
        let _ = stream.set_read_timeout(Some(left));
        match (&*stream).read(&mut buffer) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
    }
}

fn is_timeout(error: &std::io::Error) -> bool {
    matches!(error.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut)
}

/// How long a connection may be opening before a newer one may take its place when every
/// opening slot is taken.
const OPENING_GRACE: Duration = Duration::from_secs(1);
/// How long a WebSocket closed by the daemon is drained of what its client still sends.
const CLOSE_DRAIN: Duration = Duration::from_secs(1);
/// Bytes of `error` answers a client's queue may hold over its bound (see `send_reply`).
const REFUSAL_RESERVE: usize = 1 << 20;
/// How long a client over its queue's bound may go on asking without reading (`send_reply`).
const CLIENT_STALL: Duration = Duration::from_secs(5);
/// The largest WebSocket message read (a larger one closes the connection with 1009).
const WEBSOCKET_MAX_MESSAGE: usize = 1 << 20;
/// Silence from a WebSocket client after which it is pinged, and after which it is closed.
const WEBSOCKET_PING: Duration = Duration::from_secs(5);
const WEBSOCKET_SILENCE: Duration = Duration::from_secs(15);

/// How long a new connection may stay silent before it is taken for a JSON-lines client (a
/// WebSocket client opens with its HTTP request at once; a JSON-lines client that waits for
/// `hello` gets it this much later).
const SNIFF_WINDOW: Duration = Duration::from_millis(150);
/// How long a WebSocket handshake may take, from the connection.
const WEBSOCKET_HANDSHAKE: Duration = Duration::from_secs(5);
/// How often a WebSocket client's thread looks at its queue between reads.
const WEBSOCKET_POLL: Duration = Duration::from_millis(10);

/// Whether a connection's first bytes, within `SNIFF_WINDOW`, are an HTTP request (`G` of
/// `GET`: no JSON message starts with it).
fn opens_with_http(stream: &TcpStream) -> bool {
    let _ = stream.set_read_timeout(Some(SNIFF_WINDOW));
    let mut first = [0u8; 1];
    let http = matches!(stream.peek(&mut first), Ok(1) if first[0] == b'G');
    let _ = stream.set_read_timeout(None);
    http
}

fn write_loop(mut stream: TcpStream, outgoing: &Outbox) {
    while let Some(message) = outgoing.pop() {
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
