//! Policies over the network with openpi's websocket protocol (`serve_policy.py` and
//! `openpi_client`): [`RemotePolicy`] asks a policy server for action chunks as openpi's LIBERO
//! example does, and [`server`] serves our own runs to any openpi client.
//!
//! The protocol: a websocket (no compression); the server speaks first with a msgpack map of
//! metadata; then the client sends one msgpack map per request (an observation) and the server
//! answers each with a map holding `actions`, an `[H, A]` array ([`wire`]); a text frame from the
//! server is an error message (openpi sends its traceback that way, then closes).
//!
//! The observation, with openpi's LIBERO keys: `observation/image` and `observation/wrist_image`
//! (uint8 `[224, 224, 3]`: the camera image as LIBERO renders it turned by 180° — the upright
//! image mirrored left-right —, resized from the rendered side), `observation/state` (float32
//! `[8]`: eef position, eef axis-angle, finger joints), `prompt` (the instruction). Our additions,
//! ignored by openpi's input transforms: `libero_mem/episode` (a new value starts an episode),
//! `libero_mem/seed`, `libero_mem/step`, optionally `libero_mem/subgoal` (the pending subgoal's
//! text), and what a server of ours announces it reads (`libero_mem/inputs` in its metadata):
//! `libero_mem/agentview` (the upright frame at the rendered side), `libero_mem/objects` (the
//! recorder's object annotations) and `libero_mem/goal` (the goal progress).

pub mod server;
pub mod wire;

use std::collections::VecDeque;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

use rmpv::Value;
use sim::task::TaskSpec;
use sim::{Env, Observation};
use tungstenite::{Message, WebSocket};

use crate::error::EvalError;
use crate::policy::{ObjectReader, Policy};

/// Image side of openpi's LIBERO observations.
pub const OPENPI_IMAGE_SIZE: u32 = 224;
/// The camera side openpi's LIBERO example renders (then resizes to 224).
pub const OPENPI_RENDER_SIZE: usize = 256;

/// Where and how to ask a remote policy.
#[derive(Clone, Debug, PartialEq)]
pub struct RemoteConfig {
    /// `ws://HOST:PORT[/PATH]`.
    pub url: String,
    /// Actions of each returned chunk executed before the next request (openpi's `replan_steps`;
    /// capped at the chunk's length).
    pub replan_steps: usize,
    /// Send the pending subgoal's text (`libero_mem/subgoal`) with every request.
    pub send_subgoal: bool,
    /// How long to wait for the connection and for each reply.
    pub timeout: Duration,
}

impl Default for RemoteConfig {
    fn default() -> Self {
        RemoteConfig {
            url: String::new(),
            replan_steps: 5,
            send_subgoal: false,
            timeout: Duration::from_secs(60),
        }
    }
}

/// `host:port` and path of a `ws://` URL.
pub fn parse_url(url: &str) -> Result<(String, String), EvalError> {
    let bad = |why: &str| EvalError::Argument(format!("policy URL `{url}`: {why}"));
    let rest = if let Some(r) = url.strip_prefix("ws://") {
        r
    } else if url.starts_with("wss://") {
        return Err(bad("TLS (wss://) is not supported; use ws://"));
    } else {
        return Err(bad("expected ws://HOST:PORT"));
    };
    let (authority, path) = match rest.find('/') {
        Some(i) => (&rest[..i], &rest[i..]),
        None => (rest, "/"),
    };
    let port = authority
        .rsplit_once(':')
        .map(|(_, p)| p)
        .ok_or_else(|| bad("no port (ws://HOST:PORT)"))?;
    if authority.starts_with(':') || port.parse::<u16>().is_err() {
        return Err(bad("expected ws://HOST:PORT with a port number"));
    }
    Ok((authority.to_string(), path.to_string()))
}

/// A websocket to a policy server, after its metadata.
pub struct Connection {
    socket: WebSocket<TcpStream>,
    url: String,
    /// The metadata the server sent on connect.
    pub metadata: Value,
}

impl Connection {
    /// Connects (within `timeout`) and reads the server's metadata.
    pub fn open(url: &str, timeout: Duration) -> Result<Self, EvalError> {
        let (authority, _) = parse_url(url)?;
        let fail = |m: String| EvalError::Remote(format!("policy server {url}: {m}"));
        let addrs: Vec<_> = authority
            .to_socket_addrs()
            .map_err(|e| fail(format!("cannot resolve {authority}: {e}")))?
            .collect();
        let mut last = None;
        let mut stream = None;
        for a in &addrs {
            match TcpStream::connect_timeout(a, timeout) {
                Ok(s) => {
                    stream = Some(s);
                    break;
                }
                Err(e) => last = Some(e),
            }
        }
        let stream = stream.ok_or_else(|| {
            fail(format!(
                "cannot connect: {}",
                last.map_or("no address".into(), |e| e.to_string())
            ))
        })?;
        stream
            .set_read_timeout(Some(timeout))
            .and_then(|_| stream.set_write_timeout(Some(timeout)))
            .and_then(|_| stream.set_nodelay(true))
            .map_err(|e| fail(e.to_string()))?;
        let (socket, _) = tungstenite::client(url, stream)
            .map_err(|e| fail(format!("websocket handshake failed: {e}")))?;
        let mut c = Connection {
            socket,
            url: url.to_string(),
            metadata: Value::Nil,
        };
        c.metadata = c.receive().map_err(|m| fail(format!("no metadata: {m}")))?;
        Ok(c)
    }

    /// Sends one msgpack map.
    pub fn send(&mut self, v: &Value) -> Result<(), String> {
        self.socket
            .send(Message::Binary(wire::encode(v).into()))
            .map_err(|e| describe(&e))
    }

    /// The next msgpack message (pings answered; a text frame is the server's error).
    pub fn receive(&mut self) -> Result<Value, String> {
        loop {
            match self.socket.read().map_err(|e| describe(&e))? {
                Message::Binary(b) => return wire::decode(&b),
                Message::Text(t) => return Err(format!("the server failed:\n{}", t.as_str())),
                Message::Close(f) => {
                    return Err(match f {
                        Some(f) if !f.reason.is_empty() => {
                            format!("the server closed the connection ({})", f.reason)
                        }
                        _ => "the server closed the connection".into(),
                    });
                }
                _ => continue,
            }
        }
    }

    /// One request and its reply.
    pub fn infer(&mut self, request: &Value) -> Result<Value, String> {
        self.send(request)?;
        self.receive()
    }

    /// The server's URL.
    pub fn url(&self) -> &str {
        &self.url
    }
}

impl Drop for Connection {
    fn drop(&mut self) {
        let _ = self.socket.close(None);
        let _ = self.socket.flush();
    }
}

/// A websocket error in words (a read timeout says so).
fn describe(e: &tungstenite::Error) -> String {
    match e {
        tungstenite::Error::Io(io)
            if matches!(
                io.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            "no reply within the timeout".into()
        }
        tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed => {
            "the connection is closed".into()
        }
        tungstenite::Error::Protocol(p) => format!("connection lost ({p})"),
        other => other.to_string(),
    }
}

/// What a server of ours reads besides openpi's keys (its metadata's `libero_mem/inputs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Extras {
    /// The upright agentview frame at the rendered side.
    pub agentview: bool,
    /// The recorder's object annotations (state mode, oracle boxes).
    pub objects: bool,
    /// Whether those annotations need the segmentation (boxes).
    pub segmentation: bool,
}

impl Extras {
    /// Reads `libero_mem/inputs` of a server's metadata (None: not one of ours).
    pub fn from_metadata(metadata: &Value) -> Option<Extras> {
        let inputs = wire::get(metadata, "libero_mem/inputs")?;
        let flag = |k: &str| {
            wire::get(inputs, k)
                .and_then(Value::as_bool)
                .unwrap_or(false)
        };
        Some(Extras {
            agentview: flag("agentview"),
            objects: flag("objects"),
            segmentation: flag("segmentation"),
        })
    }

    /// The metadata entry announcing these extras.
    pub fn to_metadata(self) -> Value {
        wire::map(vec![
            ("agentview", Value::Boolean(self.agentview)),
            ("objects", Value::Boolean(self.objects)),
            ("segmentation", Value::Boolean(self.segmentation)),
        ])
    }
}

/// openpi's LIBERO image from one of our upright camera frames (`[S, S, 3]`): mirrored left-right
/// (LIBERO's raw frame turned by 180°, as openpi's example feeds it), resized to 224² (area
/// averaging when shrinking, as `data::imageio::resize_rgb`).
pub fn openpi_image(rgb: &[u8], side: usize) -> Vec<u8> {
    let mut data = rgb.to_vec();
    data::imageio::apply_flip(&mut data, side, side, 3, data::Flip::Horizontal);
    let img = data::RgbImage {
        width: side as u32,
        height: side as u32,
        channels: 3,
        data,
    };
    data::imageio::resize_rgb(img, OPENPI_IMAGE_SIZE, OPENPI_IMAGE_SIZE).data
}

/// A policy on a server speaking openpi's protocol (one connection per evaluation worker).
pub struct RemotePolicy {
    cfg: RemoteConfig,
    conn: Connection,
    extras: Option<Extras>,
    objects: ObjectReader,
    episode: String,
    instruction: String,
    seed: u64,
    step: usize,
    queue: VecDeque<[f32; 7]>,
}

impl RemotePolicy {
    /// Connects to `cfg.url` and reads the server's metadata.
    pub fn connect(cfg: RemoteConfig) -> Result<Self, EvalError> {
        if cfg.replan_steps == 0 {
            return Err(EvalError::Argument(
                "--replan-steps must be at least 1".into(),
            ));
        }
        let conn = Connection::open(&cfg.url, cfg.timeout)?;
        let extras = Extras::from_metadata(&conn.metadata);
        Ok(RemotePolicy {
            cfg,
            conn,
            extras,
            objects: ObjectReader::default(),
            episode: String::new(),
            instruction: String::new(),
            seed: 0,
            step: 0,
            queue: VecDeque::new(),
        })
    }

    /// The server's metadata.
    pub fn metadata(&self) -> &Value {
        &self.conn.metadata
    }

    /// The request for observation `obs` of `env`.
    pub fn request(&mut self, env: &Env, obs: &Observation) -> Result<Value, String> {
        let mut m: Vec<(&str, Value)> = Vec::new();
        let side = obs.image_size;
        let rendered = side > 0 && obs.agentview_rgb.len() == side * side * 3;
        let s = OPENPI_IMAGE_SIZE as usize;
        match self.extras {
            None => {
                if !rendered || obs.eye_in_hand_rgb.len() != side * side * 3 {
                    return Err("the environment renders no camera images".into());
                }
                m.push((
                    "observation/image",
                    wire::u8_array(&[s, s, 3], openpi_image(&obs.agentview_rgb, side)),
                ));
                m.push((
                    "observation/wrist_image",
                    wire::u8_array(&[s, s, 3], openpi_image(&obs.eye_in_hand_rgb, side)),
                ));
            }
            Some(x) => {
                if x.agentview {
                    if !rendered {
                        return Err("the environment renders no agentview image".into());
                    }
                    m.push((
                        "libero_mem/agentview",
                        wire::u8_array(&[side, side, 3], obs.agentview_rgb.clone()),
                    ));
                }
                if x.objects {
                    let objects = self.objects.read(env, obs);
                    m.push((
                        "libero_mem/objects",
                        rmpv::ext::to_value(&objects).map_err(|e| e.to_string())?,
                    ));
                }
                if let Some(g) = obs.goal.as_ref() {
                    m.push((
                        "libero_mem/goal",
                        rmpv::ext::to_value(g.progress()).map_err(|e| e.to_string())?,
                    ));
                }
            }
        }
        m.push(("observation/state", wire::f32_array(&[8], &obs.state)));
        m.push(("prompt", Value::from(self.instruction.as_str())));
        m.push(("libero_mem/episode", Value::from(self.episode.as_str())));
        m.push(("libero_mem/seed", Value::from(self.seed)));
        m.push(("libero_mem/step", Value::from(self.step as u64)));
        if self.cfg.send_subgoal {
            let pending = obs
                .goal
                .as_ref()
                .and_then(|g| g.pending.clone())
                .unwrap_or_default();
            m.push(("libero_mem/subgoal", Value::from(pending)));
        }
        Ok(wire::map(m))
    }
}

impl Policy for RemotePolicy {
    fn reset(&mut self, task: &TaskSpec, seed: u64) -> Result<(), EvalError> {
        self.episode = format!("{}@{seed}", task.id);
        self.instruction = task.instruction.clone();
        self.seed = seed;
        self.step = 0;
        self.objects = ObjectReader::default();
        self.queue.clear();
        Ok(())
    }

    fn act(&mut self, env: &Env, obs: &Observation) -> Result<[f32; 7], EvalError> {
        let step = self.step;
        let (url, episode) = (self.cfg.url.clone(), self.episode.clone());
        let fail = move |m: String| {
            EvalError::Remote(format!(
                "policy server {url}: episode {episode}, step {step}: {m}"
            ))
        };
        if self.queue.is_empty() {
            let req = self.request(env, obs).map_err(&fail)?;
            let reply = self.conn.infer(&req).map_err(&fail)?;
            let chunk = wire::read_actions(&reply).map_err(&fail)?;
            self.queue = chunk.into_iter().take(self.cfg.replan_steps).collect();
        } else if self.extras.is_some_and(|x| x.objects) {
            // The objects' labels advance once per step, also while a chunk runs open-loop.
            self.objects.read(env, obs);
        }
        self.step += 1;
        let mut a = self
            .queue
            .pop_front()
            .ok_or_else(|| fail("empty action chunk".into()))?;
        for v in a.iter_mut() {
            // Finite: `wire::read_actions` refuses a chunk with NaN or infinity.
            *v = v.clamp(-1.0, 1.0);
        }
        Ok(a)
    }

    fn needs_images(&self) -> bool {
        self.extras.is_none_or(|x| x.agentview)
    }

    fn needs_segmentation(&self) -> bool {
        self.extras.is_some_and(|x| x.segmentation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_need_ws_and_a_port() {
        assert_eq!(
            parse_url("ws://127.0.0.1:8000").unwrap(),
            ("127.0.0.1:8000".into(), "/".into())
        );
        assert_eq!(
            parse_url("ws://host:9/p/q").unwrap(),
            ("host:9".into(), "/p/q".into())
        );
        for (bad, why) in [
            ("http://h:1", "expected ws://HOST:PORT"),
            ("wss://h:1", "TLS (wss://) is not supported"),
            ("ws://host", "no port"),
            ("ws://host:x", "with a port number"),
            ("ws://:80", "with a port number"),
        ] {
            let e = parse_url(bad).unwrap_err();
            assert!(e.to_string().contains(why), "{bad}: {e}");
            assert_eq!(e.exit_code(), 2);
        }
    }

    #[test]
    fn openpi_images_are_mirrored_and_resized() {
        // A 2×2 frame: left column red, right column blue; mirrored, red is on the right.
        let rgb = vec![255, 0, 0, 0, 0, 255, 255, 0, 0, 0, 0, 255];
        let mut m = rgb.clone();
        data::imageio::apply_flip(&mut m, 2, 2, 3, data::Flip::Horizontal);
        assert_eq!(&m[..6], &[0, 0, 255, 255, 0, 0]);
        let out = openpi_image(&rgb, 2);
        assert_eq!(out.len(), 224 * 224 * 3);
        assert_eq!(&out[..3], &[0, 0, 255], "top-left is blue");
        assert_eq!(&out[out.len() - 3..], &[255, 0, 0], "bottom-right is red");
    }

    #[test]
    fn refused_connections_are_one_clear_error() {
        // A port nobody listens on (bound, then closed).
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let url = format!("ws://127.0.0.1:{port}");
        let e = RemotePolicy::connect(RemoteConfig {
            url: url.clone(),
            timeout: Duration::from_secs(2),
            ..RemoteConfig::default()
        })
        .err()
        .expect("nobody listens");
        assert!(
            e.to_string()
                .starts_with(&format!("policy server {url}: cannot connect")),
            "{e}"
        );
        assert_eq!(e.exit_code(), 2, "the --policy given is bad input");
    }
}
