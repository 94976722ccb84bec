//! A minimal hot-reload client: connects to `cirrus watch`, subscribes, and prints every event.
//! Run `cargo run --release -- watch` in one terminal and
//! `cargo run --release --example hot_reload_client [ADDR] [SINCE]` in another (ADDR defaults to
//! 127.0.0.1:7878, the bundled pipeline's `server`). It reconnects when the daemon restarts and
//! asks for what it missed with `since`. The protocol is described in docs/PROTOCOL.md.

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::time::Duration;

fn main() {
    let mut arguments = std::env::args().skip(1);
    let address = arguments.next().unwrap_or_else(|| "127.0.0.1:7878".to_string());
    let mut since: Option<u64> = arguments.next().and_then(|text| text.parse().ok());
    loop {
        match TcpStream::connect(&address) {
            Ok(stream) => {
                if let Err(error) = follow(stream, &mut since) {
                    eprintln!("connection lost: {error}");
                }
            }
            Err(error) => eprintln!("cannot connect to {address}: {error}"),
        }
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// Subscribes and prints events until the connection ends; remembers the last revision seen.
fn follow(mut stream: TcpStream, since: &mut Option<u64>) -> std::io::Result<()> {
    let request = serde_json::json!({ "type": "subscribe", "since": *since });
    stream.write_all(format!("{request}\n").as_bytes())?;
    for line in BufReader::new(stream).lines() {
        let line = line?;
        let Ok(event) = serde_json::from_str::<serde_json::Value>(&line) else {
            eprintln!("not JSON: {line}");
            continue;
        };
        match event["type"].as_str() {
            Some("hello") => println!(
                "connected: protocol {}, revision {}, output folder {}",
                event["protocol"], event["revision"], event["output"]
            ),
            Some("building") => println!("building: {} edited file(s)", event["files"].as_array().map_or(0, Vec::len)),
            Some("batch") => {
                *since = event["revision"].as_u64();
                println!("batch r{} ({} ms)", event["revision"], event["ms"]);
                for changed in event["changed"].as_array().into_iter().flatten() {
                    println!(
                        "  reload {} ({})",
                        changed["path"].as_str().unwrap_or("?"),
                        &changed["hash"].as_str().unwrap_or("?")[..12]
                    );
                }
                for removed in event["removed"].as_array().into_iter().flatten() {
                    println!("  removed {}", removed.as_str().unwrap_or("?"));
                }
                for failed in event["failed"].as_array().into_iter().flatten() {
                    let line = failed["line"].as_u64().map(|line| format!(":{line}")).unwrap_or_default();
                    println!(
                        "  FAILED {} ({}): {}{line}: {}",
                        failed["asset"],
                        failed["stage"],
                        failed["file"].as_str().unwrap_or("?"),
                        failed["message"].as_str().unwrap_or("?")
                    );
                }
            }
            Some("resync") => println!("resync at r{}: {}", event["revision"], event["message"]),
            _ => println!("{line}"),
        }
    }
    Ok(())
}
