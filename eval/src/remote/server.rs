//! `eval serve`: a run of ours behind openpi's websocket protocol, so that any openpi client (a
//! Python robot loop, another simulator, `eval --policy ws://`) can query it. Each connection
//! gets its own streaming policy (its memory), reset when `libero_mem/episode` changes (or, from
//! clients that send no episode id, when the prompt changes) and on a `{"reset": true}` message.
//!
//! What the model reads comes from the request: the state, the prompt, and, as the metadata's
//! `libero_mem/inputs` announces, `libero_mem/agentview` (else `observation/image`, mirrored back),
//! `libero_mem/objects` and `libero_mem/goal`. The reply's `actions` is the whole chunk `[H_a, 7]`,
//! each action un-normalised and finished as `eval --run` executes it (arm clamped to [−1, 1],
//! gripper ±1).

use std::net::{TcpListener, TcpStream};
use std::time::Instant;

use rmpv::Value;
use tungstenite::Message;

use super::{Extras, wire};
use crate::error::EvalError;
use crate::policy::ModelPolicy;

/// Makes one policy per connection.
pub type PolicyMaker<'a> = dyn Fn() -> Result<ModelPolicy, EvalError> + Sync + 'a;

/// What a server says about itself on connect.
#[derive(Clone, Debug, Default)]
pub struct ServerInfo {
    /// The run directory served.
    pub run: String,
    /// Its checkpoint's step.
    pub step: u64,
}

/// Serves `make`'s policies on `listener`: one thread per connection; stops after `connections`
/// connections have ended (None: serves forever). `log` gets one line per connection event.
pub fn serve(
    listener: TcpListener,
    make: &PolicyMaker,
    info: &ServerInfo,
    connections: Option<usize>,
    log: &(dyn Fn(&str) + Sync),
) -> Result<(), EvalError> {
    std::thread::scope(|scope| {
        let mut handles = Vec::new();
        for (n, stream) in listener.incoming().enumerate() {
            let stream = match stream {
                Ok(s) => s,
                Err(e) => {
                    log(&format!("connection failed: {e}"));
                    continue;
                }
            };
            handles.push(scope.spawn(move || {
                let peer = stream
                    .peer_addr()
                    .map_or_else(|_| "?".into(), |a| a.to_string());
                log(&format!("connection {n} from {peer} opened"));
                match connection(stream, make, info) {
                    Ok(requests) => {
                        log(&format!("connection {n} closed after {requests} requests"))
                    }
                    Err(e) => log(&format!("connection {n} ended: {e}")),
                }
            }));
            if connections.is_some_and(|c| n + 1 >= c) {
                break;
            }
        }
        for h in handles {
            let _ = h.join();
        }
    });
    Ok(())
}

/// The episode a connection is in.
#[derive(Default)]
struct Episode {
    id: Option<String>,
    prompt: Option<String>,
}

/// Runs one connection to its end; the number of requests answered.
fn connection(stream: TcpStream, make: &PolicyMaker, info: &ServerInfo) -> Result<usize, String> {
    stream.set_nodelay(true).map_err(|e| e.to_string())?;
    let mut ws = tungstenite::accept(stream).map_err(|e| format!("handshake: {e}"))?;
    let mut policy = match make() {
        Ok(p) => p,
        Err(e) => {
            let _ = ws.send(Message::Text(format!("cannot load the policy: {e}").into()));
            let _ = ws.close(None);
            return Err(e.to_string());
        }
    };
    let extras = Extras {
        agentview: !policy.processor().reads_state(),
        objects: policy.reads_objects(),
        segmentation: policy.processor().reads_boxes(),
    };
    let metadata = wire::map(vec![
        ("server", Value::from("libero-mem-rs eval serve")),
        ("run", Value::from(info.run.as_str())),
        ("checkpoint_step", Value::from(info.step)),
        ("libero_mem/inputs", extras.to_metadata()),
    ]);
    ws.send(Message::Binary(wire::encode(&metadata).into()))
        .map_err(|e| e.to_string())?;
    let mut episode = Episode::default();
    let mut served = 0;
    loop {
        let msg = match ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                return Ok(served);
            }
            Err(tungstenite::Error::Protocol(
                tungstenite::error::ProtocolError::ResetWithoutClosingHandshake,
            )) => return Ok(served),
            Err(e) => return Err(e.to_string()),
        };
        let bytes = match msg {
            Message::Binary(b) => b,
            Message::Close(_) => return Ok(served),
            Message::Text(_) => {
                let m = "expected a msgpack (binary) message, got text".to_string();
                let _ = ws.send(Message::Text(m.clone().into()));
                let _ = ws.close(None);
                return Err(m);
            }
            _ => continue,
        };
        let t = Instant::now();
        match answer(&mut policy, &mut episode, &bytes) {
            Ok(mut reply) => {
                if let Value::Map(m) = &mut reply {
                    m.push((
                        Value::from("server_timing"),
                        wire::map(vec![(
                            "infer_ms",
                            Value::from(t.elapsed().as_secs_f64() * 1e3),
                        )]),
                    ));
                }
                ws.send(Message::Binary(wire::encode(&reply).into()))
                    .map_err(|e| e.to_string())?;
                served += 1;
            }
            Err(m) => {
                // As openpi's server: the error as a text frame, then close.
                let _ = ws.send(Message::Text(m.clone().into()));
                let _ = ws.close(None);
                let _ = ws.flush();
                return Err(m);
            }
        }
    }
}

/// A string entry of a request.
fn text<'a>(req: &'a Value, key: &str) -> Result<Option<&'a str>, String> {
    match wire::get(req, key) {
        None | Some(Value::Nil) => Ok(None),
        Some(Value::String(s)) => s
            .as_str()
            .map(Some)
            .ok_or_else(|| format!("`{key}` is not UTF-8")),
        Some(v) => Err(format!("`{key}` is {}, expected a string", wire::kind(v))),
    }
}

/// The reply to one request.
fn answer(policy: &mut ModelPolicy, episode: &mut Episode, bytes: &[u8]) -> Result<Value, String> {
    let req = wire::decode(bytes)?;
    if !matches!(req, Value::Map(_)) {
        return Err(format!(
            "the request is {}, expected a map",
            wire::kind(&req)
        ));
    }
    if wire::get(&req, "reset").and_then(Value::as_bool) == Some(true) {
        *episode = Episode::default();
        return Ok(wire::map(vec![("reset", Value::Boolean(true))]));
    }
    let prompt = text(&req, "prompt")?.ok_or("the request has no `prompt`")?;
    let id = text(&req, "libero_mem/episode")?;
    let seed = match wire::get(&req, "libero_mem/seed") {
        None => 0,
        Some(v) => v
            .as_u64()
            .ok_or("`libero_mem/seed` is not an unsigned integer")?,
    };
    let new = match id {
        Some(id) => episode.id.as_deref() != Some(id),
        None => episode.prompt.as_deref() != Some(prompt),
    };
    if new {
        policy.start(prompt, seed);
        episode.id = id.map(str::to_string);
        episode.prompt = Some(prompt.to_string());
    }
    let state =
        wire::get(&req, "observation/state").ok_or("the request has no `observation/state`")?;
    let state = wire::read_ndarray(state, "observation/state")?.to_f32();
    let state: [f32; 8] = state.as_slice().try_into().map_err(|_| {
        format!(
            "`observation/state` has {} values, expected 8 (eef position, axis-angle, fingers)",
            state.len()
        )
    })?;
    let agentview = if policy.processor().reads_state() {
        None
    } else {
        Some(frame(&req)?)
    };
    let objects: Vec<data::ObjectAnnotation> = match wire::get(&req, "libero_mem/objects") {
        Some(v) => {
            rmpv::ext::from_value(v.clone()).map_err(|e| format!("`libero_mem/objects`: {e}"))?
        }
        None if policy.reads_objects() => {
            return Err(
                "the model reads the objects' annotations (state mode or oracle boxes): \
                        the request needs `libero_mem/objects` (as eval --policy ws:// sends to \
                        this server)"
                    .into(),
            );
        }
        None => Vec::new(),
    };
    let goal: Option<data::GoalProgress> = match wire::get(&req, "libero_mem/goal") {
        Some(v) => {
            Some(rmpv::ext::from_value(v.clone()).map_err(|e| format!("`libero_mem/goal`: {e}"))?)
        }
        None => None,
    };
    let step = model::StepObservation {
        agentview: agentview.as_ref(),
        state,
        objects: &objects,
        seed,
        instruction: prompt,
        goal: goal.as_ref(),
    };
    let chunk = policy.act_chunk(&step).map_err(|e| e.to_string())?;
    let flat: Vec<f32> = chunk.iter().flatten().copied().collect();
    Ok(wire::map(vec![(
        "actions",
        wire::f32_array(&[chunk.len(), 7], &flat),
    )]))
}

/// The upright agentview frame of a request: `libero_mem/agentview`, else openpi's
/// `observation/image` mirrored back.
fn frame(req: &Value) -> Result<data::RgbImage, String> {
    let (key, mirrored) = if wire::get(req, "libero_mem/agentview").is_some() {
        ("libero_mem/agentview", false)
    } else if wire::get(req, "observation/image").is_some() {
        ("observation/image", true)
    } else {
        return Err(
            "the model reads images: the request has neither `libero_mem/agentview` \
                    nor `observation/image`"
                .into(),
        );
    };
    let a = wire::read_ndarray(wire::get(req, key).expect("present"), key)?;
    let (h, w) = match a.shape.as_slice() {
        [h, w, 3] if a.dtype == "|u1" => (*h, *w),
        s => {
            return Err(format!(
                "`{key}` is {s:?} of `{}`, expected uint8 [H, W, 3]",
                a.dtype
            ));
        }
    };
    let mut data = a.data;
    if mirrored {
        data::imageio::apply_flip(&mut data, w, h, 3, data::Flip::Horizontal);
    }
    Ok(data::RgbImage {
        width: w as u32,
        height: h as u32,
        channels: 3,
        data,
    })
}
