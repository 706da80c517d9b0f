//! The recorder's writing, without Python per record: a queue, a writer thread, the routing of
//! records to files, and the MCAP files themselves.
//!
//! `Writer` is what `rob6_recorder.writer.Recorder` drives. `submit` copies one record into the
//! queue and returns; `submit_batch` splits a trace batch into its records (`batch`) and queues
//! them in one go. The writer thread takes records from it in order, without the GIL, and
//! writes each where it belongs:
//!
//! - one file per client session (`/session/<n>/...` records, plus everything else that happens
//!   while it is open) and a rolling system file (everything), rotated when it is
//!   `rotate_seconds` old or `rotate_bytes` large;
//! - a session file lingers `session_linger` seconds after its close event, so late bus traces of
//!   its last command still land in it; late records of a finished session go to the system
//!   file only;
//! - early ones are kept too: each service sends its traces in batches of its own, and two
//!   services' batches reach the recorder in either order, so the bus trace of a session's first
//!   command can come before the gateway's open event. The last `SESSION_BACKLOG` of records
//!   are kept, and a session file that opens starts with those logged at or after its start.
//!
//! File names: `<UTC start %Y%m%dT%H%M%SZ>_<robot>_<robot_id>_session<n>.mcap` and
//! `..._system_<part>.mcap` (part 001, 002, ... counts the rotations of this recorder run; a
//! `-2`, `-3` suffix if the name exists anyway). Every file has the URDF as an attachment, and
//! `rob6` metadata at its start and `rob6.end` at its end.
//!
//! Latched records: what the robot is made of, not what it does (the URDF on `/robot_description`,
//! the cell on `/cell`). Such a record is written where it belongs, like any other, and the latest
//! one of each latched topic again at the start of every file opened after it (a rotated system
//! file, a new session's), so every file can be read on its own.
//!
//! Crash safety: every `chunk_interval` the writer closes the open chunks and hands them to the
//! OS (and the disk, with `fsync`), so after a SIGKILL a file holds every record up to then.
//!
//! Nothing is dropped silently: above `max_backlog` queued records a record is dropped, counted
//! per topic and logged, and the accounting is written on `/recorder/status` as soon as the
//! writer catches up. Rare events (a warning, an error, a file opened) go to Python's logging
//! (`rob6.recorder`), never with the queue's lock held.
//!
//! Why native: in the running system the recorder's Python per record (routing, encoding, the
//! writer thread's wake-ups) cost the other processes' requests their tail
//! (docs/PERFORMANCE.md, "The recorder's writing, native").

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::fs::{File, OpenOptions};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Attachment, Compression, WriteOptions};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

mod batch;
use batch::Kind;

/// How long records that belong to no session are kept for a session file that opens later:
/// far more than two services' trace batches apart (5 ms).
const SESSION_BACKLOG: Duration = Duration::from_secs(2);
/// While the writer keeps up it writes this many records, then pauses, so its work comes in
/// slices with the CPU free between them: on a two-CPU machine a request beside the writer
/// waited for the whole of each burst (docs/PERFORMANCE.md, "The recorder's writing").
const WRITE_SLICE: usize = 8;
const WRITE_PAUSE: Duration = Duration::from_micros(200);
/// With more than this queued (a burst, a slow disk) it writes without pausing.
const WRITE_PAUSE_BACKLOG: usize = 2_000;
/// Woken by a record after it idled, the writer waits this long before it writes: a trace
/// batch's records are submitted one by one within a fraction of a millisecond, and a wake-up
/// for each cost the running system more than the writing itself.
const GATHER: Duration = Duration::from_millis(1);
/// At most this many records between two looks at the clock for the chunk interval.
const DRAIN_MAX: usize = 20_000;
/// Finished sessions remembered, so their late records go to the system file only.
const FINISHED_KEPT: usize = 10_000;
pub const ROBOT_DESCRIPTION_TOPIC: &str = "/robot_description";
pub const STATUS_TOPIC: &str = "/recorder/status";

// ------------------------------------------------------------------------------------ logging
/// A message on Python's `rob6.recorder` logger. Never called with the queue's lock held.
fn pylog(level: u8, message: &str) {
    Python::with_gil(|py| py_log(py, level, message));
}

/// The same from a thread that holds the GIL.
fn py_log(py: Python<'_>, level: u8, message: &str) {
    let result = py
        .import("logging")
        .and_then(|logging| logging.call_method1("getLogger", ("rob6.recorder",)))
        .and_then(|logger| logger.call_method1("log", (level, message)));
    if let Err(err) = result {
        err.print(py);
    }
}
const INFO: u8 = 20;
const WARNING: u8 = 30;
const ERROR: u8 = 40;

/// Logged at most once a second (per kind), counted always.
struct RateLimited {
    last: Option<Instant>,
}
impl RateLimited {
    fn due(&mut self) -> bool {
        let now = Instant::now();
        if self
            .last
            .is_some_and(|t| now.duration_since(t) < Duration::from_secs(1))
        {
            return false;
        }
        self.last = Some(now);
        true
    }
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// `%Y%m%dT%H%M%SZ` of a UTC time in nanoseconds.
fn utc_stamp(ns: u64) -> String {
    let t = time::OffsetDateTime::from_unix_timestamp_nanos(ns as i128).unwrap_or(time::OffsetDateTime::UNIX_EPOCH);
    format!(
        "{:04}{:02}{:02}T{:02}{:02}{:02}Z",
        t.year(),
        t.month() as u8,
        t.day(),
        t.hour(),
        t.minute(),
        t.second()
    )
}

/// A name part made safe for a file name.
fn safe(text: &str) -> String {
    let s: String = text
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '-'
            }
        })
        .collect();
    if s.is_empty() {
        "x".into()
    } else {
        s
    }
}

// ------------------------------------------------------------------------------------ the queue
struct Record {
    topic: String,
    log_time: u64,
    publish_time: u64,
    payload: Vec<u8>,
    /// the record is its session's close event
    closing: bool,
    /// written again at the start of every file opened later (see the module's text)
    latched: bool,
}

/// A command for the writer thread, queued in order with the records.
enum Control {
    Flush,
    OpenSession(String),
    CloseSession(String),
}

enum Item {
    Record(Record),
    Control(Control, Arc<Done>),
}

/// Set once by the writer thread; waited for by a caller.
#[derive(Default)]
struct Done {
    flag: Mutex<bool>,
    cond: Condvar,
}
impl Done {
    fn set(&self) {
        *self.flag.lock().unwrap() = true;
        self.cond.notify_all();
    }
    fn wait(&self, timeout: Duration) -> bool {
        let guard = self.flag.lock().unwrap();
        let (guard, _) = self.cond.wait_timeout_while(guard, timeout, |done| !*done).unwrap();
        *guard
    }
}

#[derive(Default)]
struct Accounting {
    written: u64,
    dropped: u64,
    dropped_by_topic: BTreeMap<String, u64>,
    drops_pending: BTreeMap<String, u64>,
    first_drop_ns: u64,
    last_drop_ns: u64,
    max_seen: usize,
    errors: u64,
}

struct Queue {
    items: VecDeque<Item>,
    records: usize,
    stopping: bool,
    idle: bool,
    account: Accounting,
}

struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
    schemas: Mutex<HashMap<String, (String, Vec<u8>)>>,
    paths: Mutex<Vec<String>>,
    finished: Done,
}

// ------------------------------------------------------------------------------------ one file
/// One MCAP file: channels created with a record's first write, JSON messages.
struct McapFile {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    /// the same file, read-only: its size on disk, and fsync
    handle: File,
    channels: HashMap<String, (u16, u32)>,
    schema_ids: HashMap<(String, Vec<u8>), u16>,
    messages: u64,
    pending: u64,
    opened: Instant,
}

struct FileOptions {
    chunk_size: u64,
    compression: Option<Compression>,
    level: u32,
}

impl McapFile {
    fn create(
        path: &Path,
        options: &FileOptions,
        start_ns: u64,
        urdf: Option<&str>,
        metadata: BTreeMap<String, String>,
    ) -> mcap::McapResult<Self> {
        let file = OpenOptions::new().write(true).create_new(true).open(path)?;
        let handle = File::open(path)?;
        let writer = WriteOptions::new()
            .compression(options.compression)
            .compression_level(options.level)
            .compression_threads(0) // on the writer thread, not on every core
            .chunk_size(Some(options.chunk_size))
            .profile("")
            .library("rob6-recorder")
            .create(BufWriter::with_capacity(64 << 10, file))?;
        let mut f = McapFile {
            path: path.to_path_buf(),
            writer,
            handle,
            channels: HashMap::new(),
            schema_ids: HashMap::new(),
            messages: 0,
            pending: 0,
            opened: Instant::now(),
        };
        f.writer.write_metadata(&Metadata {
            name: "rob6".into(),
            metadata,
        })?;
        if let Some(urdf) = urdf {
            f.writer.attach(&Attachment {
                log_time: start_ns,
                create_time: start_ns,
                name: "robot.urdf".into(),
                media_type: "application/xml".into(),
                data: Cow::Borrowed(urdf.as_bytes()),
            })?;
        }
        Ok(f)
    }

    fn write(
        &mut self,
        schemas: &HashMap<String, (String, Vec<u8>)>,
        topic: &str,
        log_time: u64,
        publish_time: u64,
        payload: &[u8],
    ) -> mcap::McapResult<()> {
        let (channel_id, sequence) = match self.channels.get_mut(topic) {
            Some(entry) => {
                entry.1 += 1;
                *entry
            }
            None => {
                let (name, data) = schemas.get(topic).cloned().unwrap_or_else(generic_schema);
                let schema_id = match self.schema_ids.get(&(name.clone(), data.clone())) {
                    Some(id) => *id,
                    None => {
                        let id = self.writer.add_schema(&name, "jsonschema", &data)?;
                        self.schema_ids.insert((name, data), id);
                        id
                    }
                };
                let id = self.writer.add_channel(schema_id, topic, "json", &BTreeMap::new())?;
                self.channels.insert(topic.to_string(), (id, 1));
                (id, 1)
            }
        };
        self.writer.write_to_known_channel(
            &MessageHeader {
                channel_id,
                sequence,
                log_time,
                publish_time,
            },
            payload,
        )?;
        self.messages += 1;
        self.pending += 1;
        Ok(())
    }

    /// Close the open chunk and hand everything to the OS (and the disk if `fsync`).
    fn flush(&mut self, fsync: bool) -> mcap::McapResult<()> {
        self.writer.flush()?;
        if fsync {
            self.handle.sync_data()?;
        }
        self.pending = 0;
        Ok(())
    }

    /// Bytes on disk (the open chunk not included).
    fn size(&self) -> u64 {
        self.handle.metadata().map(|m| m.len()).unwrap_or(0)
    }

    fn close(mut self, end: BTreeMap<String, String>) -> mcap::McapResult<()> {
        self.writer.write_metadata(&Metadata {
            name: "rob6.end".into(),
            metadata: end,
        })?;
        self.writer.finish()?;
        drop(self.writer); // flushes the buffer
        self.handle.sync_all()?;
        Ok(())
    }
}

fn generic_schema() -> (String, Vec<u8>) {
    ("rob6.Record".into(), br#"{"type":"object"}"#.to_vec())
}

// ------------------------------------------------------------------------------------ the files
struct Settings {
    directory: PathBuf,
    robot: String,
    robot_id: String,
    urdf: Option<String>,
    metadata: BTreeMap<String, String>,
    system: bool,
    sessions: bool,
    rotate_bytes: u64,
    rotate_seconds: f64,
    chunk_interval: Duration,
    fsync: bool,
    session_linger: Duration,
    file: FileOptions,
}

/// The open files of the recorder and the routing of records to them (the writer thread's).
struct Files {
    settings: Settings,
    shared: Arc<Shared>,
    system: Option<McapFile>,
    sessions: HashMap<String, McapFile>,
    finished: VecDeque<String>,
    finished_set: HashSet<String>,
    closing: HashMap<String, Instant>,
    recent: VecDeque<(Instant, Record)>,
    part: u32,
    /// the latest record of each latched topic, (topic, payload), in the order first latched
    latched: Vec<(String, Vec<u8>)>,
    /// what to log once the record is written: (level, message); errors are counted
    notes: Vec<(u8, String)>,
}

fn session_of(topic: &str) -> Option<&str> {
    let rest = topic.strip_prefix("/session/")?;
    let key = rest.split('/').next().unwrap_or("");
    if key.is_empty() {
        None
    } else {
        Some(key)
    }
}

/// Whether a session event record (`{"event": ...}`) ends its session.
fn event_closes(payload: &[u8]) -> bool {
    #[derive(serde::Deserialize)]
    struct Event {
        event: Option<serde_json::Value>,
    }
    match serde_json::from_slice::<Event>(payload) {
        Ok(Event {
            event: Some(serde_json::Value::String(event)),
        }) => batch::closes_session(&event),
        _ => false,
    }
}

impl Files {
    fn write(&mut self, record: Record) {
        let shared = Arc::clone(&self.shared);
        let schemas = shared.schemas.lock().unwrap();
        let Record {
            topic,
            log_time,
            publish_time,
            payload,
            closing,
            latched,
        } = &record;
        if let Some(session) = session_of(topic) {
            let is_line = topic.ends_with("/client_in") || (topic.ends_with("/event") && !closing);
            if !self.sessions.contains_key(session)
                && self.settings.sessions
                && (!self.finished_set.contains(session) || is_line)
            {
                // late records of a finished session go to the system file only; a new line or
                // open event with a reused number (gateway restarted) opens a file
                self.open_session(session.to_string(), *log_time, &schemas);
            }
            if let Some(f) = self.sessions.get_mut(session) {
                if let Err(err) = f.write(&schemas, topic, *log_time, *publish_time, payload) {
                    self.notes
                        .push((ERROR, format!("writing a record on {topic} failed: {err}")));
                }
                if *closing {
                    self.closing
                        .insert(session.to_string(), Instant::now() + self.settings.session_linger);
                }
            }
        } else {
            for f in self.sessions.values_mut() {
                if let Err(err) = f.write(&schemas, topic, *log_time, *publish_time, payload) {
                    self.notes
                        .push((ERROR, format!("writing a record on {topic} failed: {err}")));
                }
            }
        }
        if self.settings.system {
            if self.system.is_none() {
                self.system = self.open(*log_time, None, &schemas);
            }
            if let Some(f) = self.system.as_mut() {
                if let Err(err) = f.write(&schemas, topic, *log_time, *publish_time, payload) {
                    self.note_error(format!("writing a record on {topic} failed: {err}"));
                }
            }
        }
        drop(schemas);
        if *latched {
            // after the writing: a file this record opened has it once, not twice
            self.latch(record);
        } else if self.settings.sessions && session_of(&record.topic).is_none() {
            self.remember(record);
        }
    }

    /// A latched record becomes the one every file opened from now on starts with (a session
    /// file that opens later gets it from here, not from the records kept for it).
    fn latch(&mut self, record: Record) {
        match self.latched.iter_mut().find(|(topic, _)| *topic == record.topic) {
            Some(entry) => entry.1 = record.payload,
            None => self.latched.push((record.topic, record.payload)),
        }
    }

    fn note_error(&mut self, message: String) {
        self.notes.push((ERROR, message));
    }

    fn remember(&mut self, record: Record) {
        let now = Instant::now();
        while self
            .recent
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t) > SESSION_BACKLOG)
        {
            self.recent.pop_front();
        }
        self.recent.push_back((now, record));
    }

    fn open_session_now(&mut self, session: String) {
        if !self.sessions.contains_key(&session) && self.settings.sessions {
            let shared = Arc::clone(&self.shared);
            let schemas = shared.schemas.lock().unwrap();
            self.open_session(session.clone(), now_ns(), &schemas);
        }
        self.closing.remove(&session);
    }

    fn close_session(&mut self, session: String) {
        if self.sessions.contains_key(&session) {
            self.closing
                .insert(session, Instant::now() + self.settings.session_linger);
        }
    }

    fn open_session(&mut self, session: String, start_ns: u64, schemas: &HashMap<String, (String, Vec<u8>)>) {
        if self.finished_set.remove(&session) {
            self.finished.retain(|s| s != &session);
        }
        let Some(mut f) = self.open(start_ns, Some(&session), schemas) else {
            return;
        };
        for (_, r) in &self.recent {
            if r.log_time >= start_ns {
                // came before the session's first record, logged after it
                if let Err(err) = f.write(schemas, &r.topic, r.log_time, r.publish_time, &r.payload) {
                    self.notes
                        .push((ERROR, format!("writing a record on {} failed: {err}", r.topic)));
                }
            }
        }
        self.sessions.insert(session, f);
    }

    fn open(
        &mut self,
        start_ns: u64,
        session: Option<&str>,
        schemas: &HashMap<String, (String, Vec<u8>)>,
    ) -> Option<McapFile> {
        let suffix = match session {
            None => {
                self.part += 1;
                format!("system_{:03}", self.part)
            }
            Some(s) => format!("session{}", safe(s)),
        };
        let s = &self.settings;
        let base = format!(
            "{}_{}_{}_{}",
            utc_stamp(start_ns),
            safe(&s.robot),
            safe(&s.robot_id),
            suffix
        );
        let mut path = s.directory.join(format!("{base}.mcap"));
        let mut n = 2;
        while path.exists() {
            path = s.directory.join(format!("{base}-{n}.mcap"));
            n += 1;
        }
        let mut metadata = BTreeMap::from([
            ("robot".to_string(), s.robot.clone()),
            ("robot_id".to_string(), s.robot_id.clone()),
            (
                "kind".to_string(),
                if session.is_some() { "session" } else { "system" }.to_string(),
            ),
            ("started".to_string(), utc_stamp(start_ns)),
            ("start_ns".to_string(), start_ns.to_string()),
        ]);
        if let Some(session) = session {
            metadata.insert("session".into(), session.into());
        }
        for (k, v) in &s.metadata {
            metadata.insert(k.clone(), v.clone());
        }
        let latched = &self.latched;
        let opened = McapFile::create(&path, &s.file, start_ns, s.urdf.as_deref(), metadata).and_then(|mut f| {
            for (topic, payload) in latched {
                f.write(schemas, topic, start_ns, start_ns, payload)?;
            }
            f.flush(false)?;
            Ok(f)
        });
        match opened {
            Ok(f) => {
                let shown = path.display().to_string();
                self.shared.paths.lock().unwrap().push(shown.clone());
                let what = session.map_or("system".to_string(), |s| format!("session {s}"));
                self.notes.push((INFO, format!("recording {what} to {shown}")));
                Some(f)
            }
            Err(err) => {
                self.note_error(format!("opening {} failed: {err}", path.display()));
                None
            }
        }
    }

    fn flush(&mut self) {
        let fsync = self.settings.fsync;
        let mut failed = Vec::new();
        for f in self.sessions.values_mut().chain(self.system.as_mut()) {
            if f.pending > 0 {
                if let Err(err) = f.flush(fsync) {
                    failed.push(format!("flushing {} failed: {err}", f.path.display()));
                }
            }
        }
        for message in failed {
            self.note_error(message);
        }
    }

    /// End the session files whose linger is over, rotate the system file.
    fn housekeeping(&mut self, dropped_total: u64) {
        let now = Instant::now();
        let over: Vec<String> = self
            .closing
            .iter()
            .filter(|(_, when)| now >= **when)
            .map(|(s, _)| s.clone())
            .collect();
        for session in over {
            self.closing.remove(&session);
            if let Some(f) = self.sessions.remove(&session) {
                self.close_file(f, dropped_total);
                self.finished.push_back(session.clone());
                self.finished_set.insert(session);
                while self.finished.len() > FINISHED_KEPT {
                    if let Some(old) = self.finished.pop_front() {
                        self.finished_set.remove(&old);
                    }
                }
            }
        }
        let rotate = self.system.as_ref().is_some_and(|f| {
            (self.settings.rotate_seconds > 0.0 && f.opened.elapsed().as_secs_f64() >= self.settings.rotate_seconds)
                || (self.settings.rotate_bytes > 0 && f.size() >= self.settings.rotate_bytes)
        });
        if rotate {
            if let Some(f) = self.system.take() {
                self.close_file(f, dropped_total); // the next record opens the next part
            }
        }
    }

    fn close_file(&mut self, f: McapFile, dropped_total: u64) {
        let path = f.path.display().to_string();
        let end = BTreeMap::from([
            ("ended".to_string(), utc_stamp(now_ns())),
            ("messages".to_string(), f.messages.to_string()),
            ("dropped_total".to_string(), dropped_total.to_string()),
        ]);
        if let Err(err) = f.close(end) {
            self.note_error(format!("closing {path} failed: {err}"));
        }
    }

    /// Finish every open file (summary, index).
    fn finish(&mut self, dropped_total: u64) {
        let files: Vec<McapFile> = self
            .sessions
            .drain()
            .map(|(_, f)| f)
            .chain(self.system.take())
            .collect();
        for f in files {
            self.close_file(f, dropped_total);
        }
    }
}

// ------------------------------------------------------------------------------------ the writer thread
struct WriterThread {
    shared: Arc<Shared>,
    files: Files,
    error_log: RateLimited,
}

impl WriterThread {
    fn run(mut self) {
        let mut last_flush = Instant::now();
        let chunk_interval = self.files.settings.chunk_interval;
        loop {
            let mut written = 0usize;
            // take records one by one (the lock only around the queue), pacing the slices
            while written < DRAIN_MAX {
                let (item, queued, stopping) = {
                    let mut q = self.shared.queue.lock().unwrap();
                    let n = q.items.len();
                    q.account.max_seen = q.account.max_seen.max(n);
                    let item = q.items.pop_front();
                    if let Some(Item::Record(_)) = item {
                        q.records -= 1;
                    }
                    (item, n, q.stopping)
                };
                let Some(item) = item else { break };
                if written > 0 && written.is_multiple_of(WRITE_SLICE) && queued < WRITE_PAUSE_BACKLOG && !stopping {
                    std::thread::sleep(WRITE_PAUSE);
                }
                match item {
                    Item::Record(record) => {
                        self.files.write(record);
                        self.shared.queue.lock().unwrap().account.written += 1;
                    }
                    Item::Control(control, done) => {
                        match control {
                            Control::Flush => self.files.flush(),
                            Control::OpenSession(s) => self.files.open_session_now(s),
                            Control::CloseSession(s) => self.files.close_session(s),
                        }
                        done.set();
                    }
                }
                written += 1;
                self.report();
                if last_flush.elapsed() >= chunk_interval {
                    break;
                }
            }
            self.write_drop_status();
            if last_flush.elapsed() >= chunk_interval {
                self.files.flush();
                let dropped = self.shared.queue.lock().unwrap().account.dropped;
                self.files.housekeeping(dropped);
                self.report();
                last_flush = Instant::now();
            }
            let mut q = self.shared.queue.lock().unwrap();
            if q.items.is_empty() {
                if q.stopping {
                    break;
                }
                q.idle = true;
                let wait = chunk_interval.min(Duration::from_millis(250));
                let (mut q, _) = self
                    .shared
                    .wake
                    .wait_timeout_while(q, wait, |q| q.items.is_empty() && !q.stopping)
                    .unwrap();
                q.idle = false;
                let gather = !q.items.is_empty() && !q.stopping;
                drop(q);
                if gather {
                    std::thread::sleep(GATHER);
                }
            }
        }
        self.write_drop_status();
        let dropped = self.shared.queue.lock().unwrap().account.dropped;
        self.files.finish(dropped);
        self.report();
    }

    /// What the files had to say: errors (counted, logged at most once a second), files opened.
    fn report(&mut self) {
        if self.files.notes.is_empty() {
            return;
        }
        let notes: Vec<(u8, String)> = self.files.notes.drain(..).collect();
        let mut errors = 0;
        for (level, message) in notes {
            if level < ERROR {
                pylog(level, &message);
            } else {
                errors += 1;
                if self.error_log.due() {
                    pylog(level, &message);
                }
            }
        }
        self.shared.queue.lock().unwrap().account.errors += errors;
    }

    /// The drop accounting on `/recorder/status`, once the writer has caught up after drops.
    fn write_drop_status(&mut self) {
        let (status, pending, total) = {
            let mut q = self.shared.queue.lock().unwrap();
            if q.account.drops_pending.is_empty() {
                return;
            }
            let pending = std::mem::take(&mut q.account.drops_pending);
            let a = &q.account;
            let status = serde_json::json!({
                "submitted": a.written + q.records as u64, "written": a.written, "dropped": a.dropped,
                "dropped_since_last": pending, "backlog": q.items.len(), "max_backlog_seen": a.max_seen,
                "first_drop_ns": a.first_drop_ns, "last_drop_ns": a.last_drop_ns,
            });
            (status, pending, a.dropped)
        };
        let count: u64 = pending.values().sum();
        let listed: Vec<String> = pending.iter().map(|(t, c)| format!("{t}: {c}")).collect();
        pylog(
            WARNING,
            &format!(
                "recorder dropped {count} records ({}); {total} in total",
                listed.join(", ")
            ),
        );
        let now = now_ns();
        self.files.write(Record {
            topic: STATUS_TOPIC.into(),
            log_time: now,
            publish_time: now,
            payload: serde_json::to_vec(&status).unwrap_or_default(),
            closing: false,
            latched: false,
        });
        self.report();
    }
}

// ------------------------------------------------------------------------------------ Python's side
/// The recorder's queue and writer thread (see the module's text).
#[pyclass(module = "rob6_recorder_native")]
struct Writer {
    shared: Arc<Shared>,
    thread: Mutex<Option<JoinHandle<()>>>,
    pending_files: Mutex<Option<Files>>,
    max_backlog: usize,
    warn_backlog: usize,
    backlog_log: Mutex<RateLimited>,
    drop_log: Mutex<RateLimited>,
    /// the schema of each kind of record a trace batch gives (`batch::Kind::NAMED`)
    kind_schemas: HashMap<Kind, (String, Vec<u8>)>,
    /// the topics of those records whose schema is registered (not the writer's lock: it
    /// holds that one while it writes)
    batch_topics: Mutex<HashSet<String>>,
}

impl Drop for Writer {
    /// Dropped without `close` (a recorder forgotten): the writer finishes its files and ends.
    fn drop(&mut self) {
        self.shared.queue.lock().unwrap().stopping = true;
        self.shared.wake.notify_one();
    }
}

fn compression(name: &str) -> PyResult<Option<Compression>> {
    match name {
        "zstd" => Ok(Some(Compression::Zstd)),
        "lz4" => Ok(Some(Compression::Lz4)),
        "none" | "" => Ok(None),
        _ => Err(PyValueError::new_err("compression must be 'zstd', 'lz4' or 'none'")),
    }
}

impl Writer {
    /// Queue records in order, under one lock, and wake the writer if it idles (or has drops to
    /// account for); the number queued. Above `max_backlog`, or once closed, a record is dropped:
    /// counted per topic, logged at most once a second.
    fn push(&self, py: Python<'_>, records: Vec<Record>) -> usize {
        let (accepted, dropped_now, n, stopping, dropped, idle) = {
            let mut q = self.shared.queue.lock().unwrap();
            let (mut accepted, mut dropped_now) = (0, 0);
            for record in records {
                if q.stopping || q.records >= self.max_backlog {
                    let a = &mut q.account;
                    a.dropped += 1;
                    *a.dropped_by_topic.entry(record.topic.clone()).or_default() += 1;
                    *a.drops_pending.entry(record.topic).or_default() += 1;
                    if a.first_drop_ns == 0 {
                        a.first_drop_ns = record.log_time;
                    }
                    a.last_drop_ns = record.log_time;
                    dropped_now += 1;
                } else {
                    q.items.push_back(Item::Record(record));
                    q.records += 1;
                    accepted += 1;
                }
            }
            (accepted, dropped_now, q.records, q.stopping, q.account.dropped, q.idle)
        };
        if dropped_now > 0 || (accepted > 0 && idle) {
            self.shared.wake.notify_one();
        }
        if dropped_now > 0 {
            if self.drop_log.lock().unwrap().due() {
                let message = if stopping {
                    format!("recorder closed: dropping records, {dropped} dropped so far")
                } else {
                    format!(
                        "recorder backlog full ({n} records queued, limit {}): dropping records, {dropped} \
                             dropped so far",
                        self.max_backlog
                    )
                };
                py_log(py, WARNING, &message);
            }
        } else if n >= self.warn_backlog && self.backlog_log.lock().unwrap().due() {
            py_log(
                py,
                WARNING,
                &format!(
                    "recorder falling behind: {n} records queued (drops start at {})",
                    self.max_backlog
                ),
            );
        }
        accepted
    }
}

#[pymethods]
impl Writer {
    /// `metadata`: what every file's `rob6` metadata holds beside robot, robot_id, kind, started,
    /// start_ns and session; `urdf_record`: the JSON of `/robot_description`, the first latched
    /// record (in every file).
    #[new]
    #[pyo3(signature = (directory, robot, robot_id, *, urdf, urdf_record, metadata, system, sessions,
                        rotate_bytes, rotate_seconds, chunk_interval, chunk_size, compression, zstd_level,
                        fsync, max_backlog, warn_backlog, session_linger, record_schemas))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        directory: PathBuf,
        robot: String,
        robot_id: String,
        urdf: Option<String>,
        urdf_record: Option<Vec<u8>>,
        metadata: BTreeMap<String, String>,
        system: bool,
        sessions: bool,
        rotate_bytes: u64,
        rotate_seconds: f64,
        chunk_interval: f64,
        chunk_size: u64,
        compression: &str,
        zstd_level: u32,
        fsync: bool,
        max_backlog: usize,
        warn_backlog: usize,
        session_linger: f64,
        record_schemas: HashMap<String, (String, Vec<u8>)>,
    ) -> PyResult<Self> {
        let mut kind_schemas = HashMap::new();
        for (name, schema) in record_schemas {
            let Some((_, kind)) = Kind::NAMED.iter().find(|(n, _)| *n == name) else {
                return Err(PyValueError::new_err(format!("no kind of record is called {name:?}")));
            };
            kind_schemas.insert(*kind, schema);
        }
        let compression = self::compression(compression)?;
        let level = if matches!(compression, Some(Compression::Zstd)) {
            zstd_level
        } else {
            0
        };
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue {
                items: VecDeque::new(),
                records: 0,
                stopping: false,
                idle: false,
                account: Accounting::default(),
            }),
            wake: Condvar::new(),
            schemas: Mutex::new(HashMap::new()),
            paths: Mutex::new(Vec::new()),
            finished: Done::default(),
        });
        let settings = Settings {
            directory,
            robot,
            robot_id,
            urdf,
            metadata,
            system,
            sessions,
            rotate_bytes,
            rotate_seconds,
            chunk_interval: Duration::from_secs_f64(chunk_interval.max(0.001)),
            fsync,
            session_linger: Duration::from_secs_f64(session_linger.max(0.0)),
            file: FileOptions {
                chunk_size,
                compression,
                level,
            },
        };
        let files = Files {
            settings,
            shared: Arc::clone(&shared),
            system: None,
            sessions: HashMap::new(),
            finished: VecDeque::new(),
            finished_set: HashSet::new(),
            closing: HashMap::new(),
            recent: VecDeque::new(),
            part: 0,
            latched: urdf_record
                .map(|record| vec![(ROBOT_DESCRIPTION_TOPIC.to_string(), record)])
                .unwrap_or_default(),
            notes: Vec::new(),
        };
        Ok(Writer {
            shared,
            thread: Mutex::new(None),
            pending_files: Mutex::new(Some(files)),
            max_backlog,
            warn_backlog,
            backlog_log: Mutex::new(RateLimited { last: None }),
            drop_log: Mutex::new(RateLimited { last: None }),
            kind_schemas,
            batch_topics: Mutex::new(HashSet::new()),
        })
    }

    /// The JSON schema of a topic, before its first record (`schemas.schema_for`).
    fn schema(&self, topic: String, name: String, data: Vec<u8>) {
        self.shared.schemas.lock().unwrap().insert(topic, (name, data));
    }

    /// Start the writer thread (once).
    fn start(&self) {
        let Some(files) = self.pending_files.lock().unwrap().take() else {
            return;
        };
        let thread = WriterThread {
            shared: Arc::clone(&self.shared),
            files,
            error_log: RateLimited { last: None },
        };
        let shared = Arc::clone(&self.shared);
        let handle = std::thread::Builder::new()
            .name("rob6-recorder-writer".into())
            .spawn(move || {
                // never expected; a panic must not leave `close` waiting for the thread
                if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| thread.run())).is_err() {
                    pylog(
                        ERROR,
                        "the recorder's writer failed: its open files are unfinished (rob6-log recover)",
                    );
                }
                shared.finished.set();
            })
            .expect("the recorder's writer thread");
        *self.thread.lock().unwrap() = Some(handle);
    }

    /// Queue one record; never blocks. False if it had to be dropped (counted, logged). A
    /// `/session/<n>/event` record whose event ends the session closes its file (after the linger).
    /// `latched`: the record is also written at the start of every file opened after it.
    #[pyo3(signature = (topic, log_time, publish_time, payload, latched=false))]
    fn submit(
        &self,
        py: Python<'_>,
        topic: &str,
        log_time: u64,
        publish_time: u64,
        payload: &Bound<'_, PyBytes>,
        latched: bool,
    ) -> bool {
        let payload = payload.as_bytes().to_vec();
        let closing = session_of(topic).is_some() && topic.ends_with("/event") && event_closes(&payload);
        let record = Record {
            topic: topic.to_string(),
            log_time,
            publish_time,
            payload,
            closing,
            latched,
        };
        self.push(py, vec![record]) == 1
    }

    /// Queue the records of one trace batch (`batch`: client lines and replies, session events,
    /// bus traces), made here without Python; never blocks. Returns what Python records itself,
    /// `(suffix, record JSON)` (joint states, link events, logs), and with `copy` the records
    /// queued, `(topic, log_time, JSON)` (for the live view). ValueError if `payload` is not a batch.
    #[allow(clippy::type_complexity)]
    fn submit_batch<'py>(
        &self,
        py: Python<'py>,
        payload: &[u8],
        received_ns: u64,
        copy: bool,
    ) -> PyResult<(
        Vec<(String, Bound<'py, PyBytes>)>,
        Vec<(String, u64, Bound<'py, PyBytes>)>,
    )> {
        let split = batch::split(payload, received_ns)
            .map_err(|err| PyValueError::new_err(format!("not a trace batch: {err}")))?;
        for warning in &split.warnings {
            py_log(py, WARNING, warning);
        }
        {
            let mut known = self.batch_topics.lock().unwrap();
            for built in &split.built {
                if let Some(schema) = self.kind_schemas.get(&built.kind) {
                    if !known.contains(&built.topic) {
                        known.insert(built.topic.clone());
                        let mut schemas = self.shared.schemas.lock().unwrap();
                        schemas.entry(built.topic.clone()).or_insert_with(|| schema.clone());
                    }
                }
            }
        }
        let copies = if copy {
            let to_py = |b: &batch::Built| (b.topic.clone(), b.log_time, PyBytes::new(py, &b.payload));
            split.built.iter().map(to_py).collect()
        } else {
            Vec::new()
        };
        let records = split.built.into_iter().map(|b| Record {
            topic: b.topic,
            log_time: b.log_time,
            publish_time: b.publish_time,
            payload: b.payload,
            closing: b.closing,
            latched: false,
        });
        self.push(py, records.collect());
        let others = split
            .others
            .into_iter()
            .map(|(suffix, record)| (suffix, PyBytes::new(py, &record)))
            .collect();
        Ok((others, copies))
    }

    /// A command for the writer thread, in order with the records: `flush`, `open_session`,
    /// `close_session`; with `wait` (s), block until it is done (False if not within it).
    #[pyo3(signature = (kind, arg=None, wait=None))]
    fn control(&self, py: Python<'_>, kind: &str, arg: Option<String>, wait: Option<f64>) -> PyResult<bool> {
        let control = match (kind, arg) {
            ("flush", _) => Control::Flush,
            ("open_session", Some(s)) => Control::OpenSession(s),
            ("close_session", Some(s)) => Control::CloseSession(s),
            _ => return Err(PyValueError::new_err(format!("unknown recorder control {kind:?}"))),
        };
        let done = Arc::new(Done::default());
        self.shared
            .queue
            .lock()
            .unwrap()
            .items
            .push_back(Item::Control(control, Arc::clone(&done)));
        self.shared.wake.notify_one();
        let started = self.thread.lock().unwrap().is_some();
        match wait {
            Some(seconds) if started => Ok(py.allow_threads(|| done.wait(Duration::from_secs_f64(seconds.max(0.0))))),
            _ => Ok(true),
        }
    }

    /// Write everything queued, finish every file and stop; False if the writer did not
    /// finish within `timeout` s. Records submitted after it are dropped (counted).
    fn close(&self, py: Python<'_>, timeout: f64) -> PyResult<bool> {
        self.start(); // write whatever was queued before start()
        self.shared.queue.lock().unwrap().stopping = true;
        self.shared.wake.notify_one();
        let finished = py.allow_threads(|| self.shared.finished.wait(Duration::from_secs_f64(timeout.max(0.0))));
        if !finished {
            let queued = self.shared.queue.lock().unwrap().records;
            py_log(
                py,
                ERROR,
                &format!("recorder writer did not finish within {timeout} s ({queued} records queued)"),
            );
            return Ok(false);
        }
        if let Some(handle) = self.thread.lock().unwrap().take() {
            handle
                .join()
                .map_err(|_| PyRuntimeError::new_err("the recorder's writer thread failed"))?;
        }
        Ok(true)
    }

    /// The accounting: submitted, written, dropped, dropped_by_topic, backlog, max_backlog_seen,
    /// errors, files (every file opened so far).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        {
            let q = self.shared.queue.lock().unwrap();
            let a = &q.account;
            d.set_item("submitted", a.written + q.records as u64)?;
            d.set_item("written", a.written)?;
            d.set_item("dropped", a.dropped)?;
            d.set_item("dropped_by_topic", a.dropped_by_topic.clone())?;
            d.set_item("backlog", q.items.len())?;
            d.set_item("max_backlog_seen", a.max_seen)?;
            d.set_item("errors", a.errors)?;
        }
        d.set_item("files", self.shared.paths.lock().unwrap().clone())?;
        Ok(d)
    }
}

#[pymodule]
fn rob6_recorder_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Writer>()?;
    m.add("STATUS_TOPIC", STATUS_TOPIC)?;
    m.add("ROBOT_DESCRIPTION_TOPIC", ROBOT_DESCRIPTION_TOPIC)?;
    Ok(())
}
