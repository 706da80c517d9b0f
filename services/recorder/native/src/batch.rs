//! A trace batch split into the records the recorder writes, without Python per record.
//!
//! A batch (`rob6/<id>/trace/<service>`, `rob6.bus.trace`) is a JSON array of `[suffix, record]`
//! pairs. Three kinds become records here:
//!
//! - `trace/gateway/session` (a client line and its reply, `rob6.messages.ClientExchange`):
//!   `/session/<n>/client_in` at the line's arrival and `/session/<n>/client_out` at the reply;
//! - `trace/gateway/event` (a session opening or closing, `rob6.messages.SessionEvent`):
//!   `/session/<n>/event`, and the greeting on `/session/<n>/client_out`;
//! - `trace/<service>/<op>` (a request a service served, `rob6.bus.serve`):
//!   `/bus/<service>/<op>/request` at `t` and `/bus/<service>/<op>/reply` at `t + dt`, both with
//!   the envelope's `cid`. The bodies are passed through as the service sent them, never decoded:
//!   a BackwardCalc's trace holds some 50 numbers.
//!
//! A bus trace of an unexpected shape still gives both records (what is there kept as the body,
//! the time it was received); a session record that cannot be read is kept as it came, on
//! `/<suffix>`, with a warning. Every other suffix (joint states, link events, logs) goes back to
//! Python, which derives from them (`/tf`, `/flange`, `foxglove.Log`).

use serde::{Deserialize, Serialize};
use serde_json::value::RawValue;
use serde_json::Value;

/// One record, made here: its topic, times and JSON.
pub struct Built {
    pub topic: String,
    pub kind: Kind,
    pub log_time: u64,
    pub publish_time: u64,
    pub payload: Vec<u8>,
    /// the record is its session's close event
    pub closing: bool,
}

impl Built {
    fn new(topic: String, kind: Kind, log_time: u64, publish_time: u64, payload: Vec<u8>) -> Self {
        Built {
            topic,
            kind,
            log_time,
            publish_time,
            payload,
            closing: false,
        }
    }
}

/// What a built record is, for its schema (`rob6_recorder.schemas`).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Kind {
    ClientIn,
    ClientOut,
    Event,
    Request,
    Reply,
    /// kept as it came (a record that could not be read)
    Kept,
}

impl Kind {
    pub const NAMED: [(&'static str, Kind); 5] = [
        ("client_in", Kind::ClientIn),
        ("client_out", Kind::ClientOut),
        ("event", Kind::Event),
        ("request", Kind::Request),
        ("reply", Kind::Reply),
    ];
}

/// A batch's parts: the records made here, in order; what goes back to Python as
/// `(suffix, record JSON)`; warnings to log.
#[derive(Default)]
pub struct Split {
    pub built: Vec<Built>,
    pub others: Vec<(String, Vec<u8>)>,
    pub warnings: Vec<String>,
}

/// Split one batch; an error if it is not a JSON array of `[suffix, record]` pairs.
pub fn split(payload: &[u8], received_ns: u64) -> Result<Split, serde_json::Error> {
    let pairs: Vec<(String, &RawValue)> = serde_json::from_slice(payload)?;
    let mut out = Split::default();
    for (suffix, record) in pairs {
        let made = match suffix.as_str() {
            "trace/gateway/session" => exchange(record.get(), &mut out.built),
            "trace/gateway/event" => event(record.get(), &mut out.built),
            _ => match suffix.strip_prefix("trace/").and_then(|rest| rest.split_once('/')) {
                Some((service, op)) => {
                    bus_trace(service, op, record.get(), received_ns, &mut out.built);
                    Ok(())
                }
                None => {
                    out.others.push((suffix, record.get().as_bytes().to_vec()));
                    continue;
                }
            },
        };
        if let Err(err) = made {
            out.warnings.push(format!(
                "{suffix}: a record that could not be read ({err}), kept as it came"
            ));
            out.built.push(Built::new(
                format!("/{suffix}"),
                Kind::Kept,
                received_ns,
                received_ns,
                record.get().as_bytes().to_vec(),
            ));
        }
    }
    Ok(out)
}

/// Whether a session event ends its session (its file then lingers and closes).
pub fn closes_session(event: &str) -> bool {
    const CLOSING: [&str; 6] = ["close", "closed", "disconnect", "disconnected", "end", "lost"];
    CLOSING.contains(&event.to_lowercase().as_str())
}

/// Nanoseconds of a time in seconds, truncated as Python's `int(t * 1e9)`; never before 1970.
fn truncated_ns(t: f64) -> u64 {
    (t * 1e9).max(0.0) as u64
}

/// A record read from a JSON object (serde would also read a struct from an array, field by field).
fn object<'a, T: Deserialize<'a>>(record: &'a str) -> serde_json::Result<T> {
    if record.trim_start().starts_with('{') {
        serde_json::from_str(record)
    } else {
        Err(serde::de::Error::custom("not a JSON object"))
    }
}

fn json(value: &impl Serialize) -> Vec<u8> {
    serde_json::to_vec(value).expect("a record of strings, numbers and JSON is always JSON")
}

// ------------------------------------------------------------------------------------ sessions
#[derive(Deserialize)]
struct Exchange {
    session: i64,
    peer: String,
    cid: String,
    t_in: f64,
    t_out: f64,
    line: String,
    reply: Option<String>,
    #[serde(default)]
    seq: i64,
}

#[derive(Serialize)]
struct ClientIn<'a> {
    session: i64,
    cid: &'a str,
    text: String,
    peer: &'a str,
    seq: i64,
}

#[derive(Serialize)]
struct ClientOut<'a> {
    session: i64,
    cid: &'a str,
    text: &'a str,
    dt: f64,
    seq: i64,
}

fn exchange(record: &str, built: &mut Vec<Built>) -> serde_json::Result<()> {
    let x: Exchange = object(record)?;
    let line = ClientIn {
        session: x.session,
        cid: &x.cid,
        text: format!("{}\n", x.line),
        peer: &x.peer,
        seq: x.seq,
    };
    let reply = ClientOut {
        session: x.session,
        cid: &x.cid,
        text: x.reply.as_deref().unwrap_or(""),
        dt: x.t_out - x.t_in,
        seq: x.seq,
    };
    let (t_in, t_out) = (truncated_ns(x.t_in), truncated_ns(x.t_out));
    built.push(Built::new(
        format!("/session/{}/client_in", x.session),
        Kind::ClientIn,
        t_in,
        t_in,
        json(&line),
    ));
    built.push(Built::new(
        format!("/session/{}/client_out", x.session),
        Kind::ClientOut,
        t_out,
        t_out,
        json(&reply),
    ));
    Ok(())
}

#[derive(Deserialize)]
struct Event {
    session: i64,
    event: String,
    peer: String,
    t: f64,
    #[serde(default)]
    greeting: String,
    #[serde(default)]
    reason: String,
}

#[derive(Serialize)]
struct EventRecord<'a> {
    session: i64,
    event: &'a str,
    peer: &'a str,
    /// a close other than by Quit or the client's close between commands
    #[serde(skip_serializing_if = "str::is_empty")]
    reason: &'a str,
}

#[derive(Serialize)]
struct Greeting<'a> {
    session: i64,
    cid: &'a str,
    text: &'a str,
    kind: &'a str,
}

fn event(record: &str, built: &mut Vec<Built>) -> serde_json::Result<()> {
    let e: Event = object(record)?;
    let t = truncated_ns(e.t);
    let record = EventRecord {
        session: e.session,
        event: &e.event,
        peer: &e.peer,
        reason: &e.reason,
    };
    let mut event = Built::new(
        format!("/session/{}/event", e.session),
        Kind::Event,
        t,
        t,
        json(&record),
    );
    event.closing = closes_session(&e.event);
    built.push(event);
    if !e.greeting.is_empty() {
        let greeting = Greeting {
            session: e.session,
            cid: "",
            text: &e.greeting,
            kind: "greeting",
        };
        built.push(Built::new(
            format!("/session/{}/client_out", e.session),
            Kind::ClientOut,
            t,
            t,
            json(&greeting),
        ));
    }
    Ok(())
}

// ------------------------------------------------------------------------------------ bus traces
/// A trace as the service wrote it; any value is taken (a record is never lost to a field of an
/// unexpected type), the envelopes undecoded.
#[derive(Deserialize)]
struct Trace<'a> {
    #[serde(borrow, default)]
    t: Option<&'a RawValue>,
    #[serde(borrow, default)]
    dt: Option<&'a RawValue>,
    #[serde(borrow, default)]
    instance: Option<&'a RawValue>,
    #[serde(borrow, default)]
    request: Option<&'a RawValue>,
    #[serde(borrow, default)]
    reply: Option<&'a RawValue>,
}

/// The parts of a request or reply envelope a record keeps; the body as it is.
#[derive(Deserialize)]
struct Envelope<'a> {
    #[serde(default)]
    cid: Value,
    #[serde(default)]
    ok: Value,
    #[serde(borrow, default)]
    body: Option<&'a RawValue>,
    #[serde(borrow, default)]
    error: Option<&'a RawValue>,
}

#[derive(Serialize)]
struct RequestRecord<'a> {
    cid: &'a str,
    service: &'a str,
    op: &'a str,
    instance: &'a RawValue,
    body: &'a RawValue,
}

#[derive(Serialize)]
struct ReplyRecord<'a> {
    cid: &'a str,
    service: &'a str,
    op: &'a str,
    instance: &'a RawValue,
    ok: bool,
    body: &'a RawValue,
    dt: f64,
    /// only when the reply has one
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<&'a RawValue>,
}

fn null() -> &'static RawValue {
    serde_json::from_str("null").expect("null is JSON")
}

/// A JSON number as f64 (a boolean or anything else is none).
fn number(raw: Option<&RawValue>) -> Option<f64> {
    raw.and_then(|r| serde_json::from_str::<f64>(r.get()).ok())
}

/// The envelope, or none when the trace holds something else there (kept as the body).
fn open(raw: Option<&RawValue>) -> Option<Envelope<'_>> {
    raw.and_then(|r| object(r.get()).ok())
}

/// Python's truth of a JSON value.
fn truthy(v: &Value) -> bool {
    match v {
        Value::Null => false,
        Value::Bool(b) => *b,
        Value::Number(n) => n.as_f64().is_some_and(|f| f != 0.0),
        Value::String(s) => !s.is_empty(),
        Value::Array(a) => !a.is_empty(),
        Value::Object(o) => !o.is_empty(),
    }
}

/// The correlation id: the request's, else the reply's; a string as it is, another value as its JSON.
fn cid_of(request: Option<&Envelope>, reply: Option<&Envelope>) -> String {
    [request, reply]
        .into_iter()
        .flatten()
        .map(|e| &e.cid)
        .find(|cid| truthy(cid))
        .map(|cid| match cid {
            Value::String(s) => s.clone(),
            other => other.to_string(),
        })
        .unwrap_or_default()
}

fn bus_trace(service: &str, op: &str, record: &str, received_ns: u64, built: &mut Vec<Built>) {
    // not an object: all of it kept as the request's body
    let trace: Trace = object(record).unwrap_or(Trace {
        t: None,
        dt: None,
        instance: None,
        request: serde_json::from_str(record).ok(),
        reply: None,
    });
    let dt = number(trace.dt).unwrap_or(0.0);
    let start = match number(trace.t) {
        Some(t) => (t * 1e9).round_ties_even().max(0.0) as u64,
        None => received_ns,
    };
    let end = (i128::from(start) + (dt * 1e9).round_ties_even() as i128).max(0) as u64;
    let (request, reply) = (open(trace.request), open(trace.reply));
    let cid = cid_of(request.as_ref(), reply.as_ref());
    let empty: &RawValue = serde_json::from_str("\"\"").expect("a string is JSON");
    let instance = trace.instance.unwrap_or(empty);
    let request_body = match &request {
        Some(e) => e.body.unwrap_or(null()),
        None => trace.request.unwrap_or(null()),
    };
    let (ok, reply_body, error) = match &reply {
        Some(e) => (
            truthy(&e.ok),
            e.body.unwrap_or(null()),
            e.error.filter(|r| r.get() != "null"),
        ),
        None => (false, trace.reply.unwrap_or(null()), None),
    };
    built.push(Built::new(
        format!("/bus/{service}/{op}/request"),
        Kind::Request,
        start,
        start,
        json(&RequestRecord {
            cid: &cid,
            service,
            op,
            instance,
            body: request_body,
        }),
    ));
    built.push(Built::new(
        format!("/bus/{service}/{op}/reply"),
        Kind::Reply,
        end,
        received_ns,
        json(&ReplyRecord {
            cid: &cid,
            service,
            op,
            instance,
            ok,
            body: reply_body,
            dt,
            error,
        }),
    ));
}
