//! A client of the Foxglove WebSocket protocol (subprotocol `foxglove.sdk.v1`, the same
//! messages as `foxglove.websocket.v1`): what `afs bench stack` attaches to the live view and
//! what the tests read it with. It speaks the protocol itself over `tungstenite`, as Foxglove
//! does, so that a test exercises the server as a viewer would: the server's `serverInfo` and
//! `advertise` (JSON text), the client's `subscribe`, and the server's binary message data
//! (opcode 1, subscription id u32, log time u64, payload; little-endian).

use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

/// The subprotocol asked for.
pub const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// One advertised channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Advertised {
    /// Channel id.
    pub id: u64,
    /// Topic.
    pub topic: String,
    /// Message encoding (`json`).
    pub encoding: String,
    /// Schema name.
    pub schema_name: String,
    /// Schema encoding (`jsonschema`).
    pub schema_encoding: String,
    /// The schema.
    pub schema: String,
}

/// One message received.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    /// Its topic.
    pub topic: String,
    /// Its log time (ns).
    pub log_time_ns: u64,
    /// Its payload (JSON).
    pub payload: Vec<u8>,
}

/// A connected client.
pub struct ViewClient {
    ws: WebSocket<TcpStream>,
    /// The server's name (from `serverInfo`).
    pub server_name: String,
    /// The channels advertised so far, by topic.
    pub channels: BTreeMap<String, Advertised>,
    subscriptions: BTreeMap<u32, String>,
}

impl ViewClient {
    /// Connects to `url` (`ws://HOST:PORT`), retrying until `within` has passed (the server
    /// may still be starting), and reads the server's greeting.
    pub fn connect(url: &str, within: Duration) -> Result<Self> {
        let addr = url
            .strip_prefix("ws://")
            .with_context(|| format!("'{url}' is not a ws:// address"))?
            .trim_end_matches('/')
            .to_string();
        let t0 = Instant::now();
        let stream = loop {
            match TcpStream::connect(&addr) {
                Ok(s) => break s,
                Err(e) if t0.elapsed() > within => {
                    return Err(e).with_context(|| format!("connecting to the live view at {url}"));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        };
        stream.set_nodelay(true)?;
        let mut req = url.into_client_request()?;
        req.headers_mut()
            .insert("Sec-WebSocket-Protocol", SUBPROTOCOL.parse()?);
        let (ws, resp) = tungstenite::client(req, stream)
            .map_err(|e| anyhow::anyhow!("WebSocket handshake with {url}: {e}"))?;
        let proto = resp
            .headers()
            .get("Sec-WebSocket-Protocol")
            .and_then(|v| v.to_str().ok());
        if proto != Some(SUBPROTOCOL) {
            bail!("the server at {url} answered with subprotocol {proto:?}, not {SUBPROTOCOL}");
        }
        let mut c = Self {
            ws,
            server_name: String::new(),
            channels: BTreeMap::new(),
            subscriptions: BTreeMap::new(),
        };
        c.set_timeout(Some(Duration::from_millis(200)))?;
        Ok(c)
    }

    fn set_timeout(&mut self, t: Option<Duration>) -> Result<()> {
        self.ws.get_ref().set_read_timeout(t)?;
        Ok(())
    }

    /// Reads until every topic of `topics` is advertised (or `within` passes).
    pub fn wait_for(&mut self, topics: &[&str], within: Duration) -> Result<()> {
        let t0 = Instant::now();
        while !topics.iter().all(|t| self.channels.contains_key(*t)) {
            if t0.elapsed() > within {
                bail!(
                    "the live view advertised {:?}, not all of {topics:?}, within {within:?}",
                    self.channels.keys().collect::<Vec<_>>()
                );
            }
            self.read_one()?;
        }
        Ok(())
    }

    /// Subscribes to `topics` (each must be advertised).
    pub fn subscribe(&mut self, topics: &[&str]) -> Result<()> {
        let mut subs = Vec::new();
        for t in topics {
            let ch = self
                .channels
                .get(*t)
                .with_context(|| format!("topic {t} is not advertised"))?;
            let id = self.subscriptions.len() as u32 + 1;
            self.subscriptions.insert(id, (*t).to_string());
            subs.push(serde_json::json!({"id": id, "channelId": ch.id}));
        }
        let msg = serde_json::json!({"op": "subscribe", "subscriptions": subs});
        self.ws
            .send(Message::text(msg.to_string()))
            .context("sending subscribe")?;
        Ok(())
    }

    /// The next message on a subscribed topic, or None if none came within the read timeout.
    pub fn next_message(&mut self) -> Result<Option<Received>> {
        self.read_one()
    }

    /// Reads one frame; handles control messages; returns message data.
    fn read_one(&mut self) -> Result<Option<Received>> {
        let msg = match self.ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(None);
            }
            Err(e) => return Err(e).context("reading from the live view"),
        };
        match msg {
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str())
                    .context("a server message that is not JSON")?;
                match v["op"].as_str() {
                    Some("serverInfo") => {
                        self.server_name = v["name"].as_str().unwrap_or_default().to_string();
                    }
                    Some("advertise") => {
                        for c in v["channels"].as_array().into_iter().flatten() {
                            let s = |k: &str| c[k].as_str().unwrap_or_default().to_string();
                            let a = Advertised {
                                id: c["id"].as_u64().unwrap_or(u64::MAX),
                                topic: s("topic"),
                                encoding: s("encoding"),
                                schema_name: s("schemaName"),
                                schema_encoding: s("schemaEncoding"),
                                schema: s("schema"),
                            };
                            self.channels.insert(a.topic.clone(), a);
                        }
                    }
                    _ => {}
                }
                Ok(None)
            }
            Message::Binary(b) => {
                if b.len() < 13 || b[0] != 1 {
                    return Ok(None);
                }
                let sub = u32::from_le_bytes(b[1..5].try_into().expect("4 bytes"));
                let log_time_ns = u64::from_le_bytes(b[5..13].try_into().expect("8 bytes"));
                let Some(topic) = self.subscriptions.get(&sub) else {
                    bail!("message data for subscription {sub}, which this client never made");
                };
                Ok(Some(Received {
                    topic: topic.clone(),
                    log_time_ns,
                    payload: b[13..].to_vec(),
                }))
            }
            Message::Close(_) => bail!("the live view closed the connection"),
            _ => Ok(None),
        }
    }
}
