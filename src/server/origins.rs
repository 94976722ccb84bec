//! Which browser pages may open the daemon's WebSocket: pages served from this machine, those
//! `--allow-origin` names, and clients that send no `Origin` (engines and tools, not browsers).

/// The WebSocket handshake's answer: a page that `origin_allowed` refuses gets 403 Forbidden.
#[allow(clippy::result_large_err)] // tungstenite's error response type, not ours to box
pub(super) fn check_origin(
    request: &tungstenite::handshake::server::Request,
    response: tungstenite::handshake::server::Response,
    origins: &[String],
) -> Result<tungstenite::handshake::server::Response, tungstenite::handshake::server::ErrorResponse> {
    let origin = request.headers().get("origin").map(|origin| String::from_utf8_lossy(origin.as_bytes()));
    match origin {
        Some(origin) if !origin_allowed(&origin, origins) => {
            tracing::warn!(
                "hot-reload server: refused a WebSocket from the page at {origin} (not a loopback page, nor one of \
                 `--allow-origin`)"
            );
            let mut refusal = tungstenite::handshake::server::ErrorResponse::new(Some(format!(
                "pages from {origin} may not connect: start the daemon with --allow-origin {origin}\n"
            )));
            *refusal.status_mut() = tungstenite::http::StatusCode::FORBIDDEN;
            Err(refusal)
        }
        _ => Ok(response),
    }
}

/// Whether a browser page at `origin` may open a WebSocket: loopback pages (`http(s)://`
/// `localhost`, `127.x.x.x` or `[::1]`, any port) and those `allowed` names exactly (`*` allows
/// every page).
fn origin_allowed(origin: &str, allowed: &[String]) -> bool {
    if allowed.iter().any(|allowed| allowed == "*" || allowed.trim_end_matches('/') == origin) {
        return true;
    }
    let Some(rest) = origin.strip_prefix("http://").or_else(|| origin.strip_prefix("https://")) else {
        return false;
    };
    let host = match rest.strip_prefix('[') {
        Some(bracketed) => bracketed.split_once(']').map_or("", |(host, _)| host),
        None => rest.split(':').next().unwrap_or(""),
    };
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|address| address.is_loopback())
}
