//! Recording every topic of a running stack to MCAP (JSON messages with a JSON schema per
//! topic, zstd-compressed chunks: Foxglove opens it as is), and reading it back for `afs plot`
//! and the CSV export.
//!
//! The supervisor hands samples to a writer thread through a bounded channel; the thread
//! serialises and writes them in the order received. A full channel drops the sample and
//! counts it (the summary reports the count), so a slow disk can never stall the supervisor.

use super::topics::{Rec, TOPICS, json_schema};
use anyhow::{Context, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

/// What a recording holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct RecordSummary {
    /// The file.
    pub path: PathBuf,
    /// Messages written per topic.
    pub messages: BTreeMap<String, u64>,
    /// Samples dropped because the writer fell behind.
    pub dropped: u64,
    /// Samples offered to the recording: every one is written (`messages`) or dropped.
    #[serde(default)]
    pub offered: u64,
    /// File size (bytes).
    pub bytes: u64,
}

/// A recording in progress.
pub struct Recorder {
    tx: SyncSender<Rec>,
    dropped: u64,
    offered: u64,
    handle: JoinHandle<Result<RecordSummary>>,
}

/// Samples the channel holds before dropping: about 13 s of the stack's streams at their
/// fullest (the insertion at 10 kHz offers 47 000 a second); std's bounded channel allocates and
/// touches its 600 000 slots (240 bytes and a stamp each, about 150 MB) when a recording starts. On
/// 2 cores the writer (JSON, zstd) can fall behind the stack for a whole 10-s run: with
/// 200 000 (4 s), the insertion's stack test lost 1–6 % of its samples in 2 runs of 5.
const QUEUE: usize = 600_000;

impl Recorder {
    /// Starts recording to `path` (created or truncated).
    pub fn start(path: &Path) -> Result<Self> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("creating recording {}", path.display()))?;
        let (tx, rx) = sync_channel(QUEUE);
        let p = path.to_path_buf();
        let handle = std::thread::Builder::new()
            .name("afs-recorder".into())
            .spawn(move || write_all(file, rx, p))
            .context("starting the recorder thread")?;
        Ok(Self {
            tx,
            dropped: 0,
            offered: 0,
            handle,
        })
    }

    /// Queues a sample; never blocks.
    pub fn push(&mut self, r: Rec) {
        self.offered += 1;
        match self.tx.try_send(r) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }

    /// Flushes and closes the file.
    pub fn finish(self) -> Result<RecordSummary> {
        drop(self.tx);
        let mut s = self
            .handle
            .join()
            .map_err(|_| anyhow::anyhow!("the recorder thread panicked"))??;
        s.dropped += self.dropped;
        s.offered = self.offered;
        Ok(s)
    }
}

fn write_all(file: std::fs::File, rx: Receiver<Rec>, path: PathBuf) -> Result<RecordSummary> {
    let opts = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .library("afs");
    let mut w = opts
        .create(BufWriter::new(file))
        .context("starting the MCAP file")?;
    let mut channels = Vec::new();
    for (topic, ty) in TOPICS {
        let schema = w
            .add_schema(ty, "jsonschema", json_schema(ty).as_bytes())
            .context("MCAP schema")?;
        let ch = w
            .add_channel(schema, topic, "json", &BTreeMap::new())
            .context("MCAP channel")?;
        channels.push(ch);
    }
    let mut counts = [0u64; TOPICS.len()];
    let mut summary = RecordSummary {
        path: path.clone(),
        ..Default::default()
    };
    for r in rx {
        let c = r.channel();
        let Ok(data) = r.json() else {
            summary.dropped += 1;
            continue;
        };
        let t = r.publish_ns();
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channels[c],
                sequence: counts[c] as u32,
                log_time: t,
                publish_time: t,
            },
            &data,
        )
        .context("writing the recording")?;
        counts[c] += 1;
    }
    w.finish().context("closing the recording")?;
    drop(w);
    for (i, (topic, _)) in TOPICS.iter().enumerate() {
        summary.messages.insert((*topic).into(), counts[i]);
    }
    summary.bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
    Ok(summary)
}

/// Every message of a recording, by topic, as JSON values in recorded order.
pub fn read(path: &Path) -> Result<BTreeMap<String, Vec<serde_json::Value>>> {
    let mut out: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    each_message(path, |topic, data| {
        out.entry(topic.to_string())
            .or_default()
            .push(parse(topic, data)?);
        Ok(())
    })?;
    Ok(out)
}

/// A message's JSON.
fn parse(topic: &str, data: &[u8]) -> Result<serde_json::Value> {
    serde_json::from_slice(data).with_context(|| format!("a message on {topic} is not JSON"))
}

/// Calls `f` with each message's topic and JSON bytes, in recorded order, holding one message
/// at a time: a recording is read without being parsed whole.
fn each_message(path: &Path, mut f: impl FnMut(&str, &[u8]) -> Result<()>) -> Result<()> {
    let bytes =
        std::fs::read(path).with_context(|| format!("reading recording {}", path.display()))?;
    let stream = mcap::MessageStream::new(&bytes)
        .with_context(|| format!("{} is not an MCAP file", path.display()))?;
    for m in stream {
        let m = m.with_context(|| format!("a damaged record in {}", path.display()))?;
        f(&m.channel.topic, &m.data)?;
    }
    Ok(())
}

/// A message's fields as CSV columns (`a.b`, `a[i]`) and values (strings without their JSON
/// quotes, null as empty), in buffers kept from one message to the next: a long recording is
/// exported without an allocation per field.
#[doc(hidden)]
#[derive(Default)]
pub struct Flat {
    keys: Vec<String>,
    values: Vec<String>,
    len: usize,
    key: String,
}

impl Flat {
    /// Flattens `v`, replacing the last message's fields.
    pub fn fill(&mut self, v: &serde_json::Value) {
        self.len = 0;
        self.key.clear();
        self.visit(v);
    }

    fn visit(&mut self, v: &serde_json::Value) {
        use std::fmt::Write;
        let at = self.key.len();
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    if at > 0 {
                        self.key.push('.');
                    }
                    self.key.push_str(k);
                    self.visit(x);
                    self.key.truncate(at);
                }
                return;
            }
            serde_json::Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    let _ = write!(self.key, "[{i}]");
                    self.visit(x);
                    self.key.truncate(at);
                }
                return;
            }
            _ => {}
        }
        if self.len == self.keys.len() {
            self.keys.push(String::new());
            self.values.push(String::new());
        }
        let (key, value) = (&mut self.keys[self.len], &mut self.values[self.len]);
        key.clear();
        key.push_str(&self.key);
        value.clear();
        match v {
            serde_json::Value::String(text) => value.push_str(text),
            serde_json::Value::Null => {}
            other => {
                let _ = write!(value, "{other}");
            }
        }
        self.len += 1;
    }

    /// The columns.
    pub fn keys(&self) -> &[String] {
        &self.keys[..self.len]
    }

    /// The values, one per column.
    pub fn values(&self) -> &[String] {
        &self.values[..self.len]
    }
}

/// One topic's CSV file: its columns are its first message's fields.
struct TopicCsv {
    writer: csv::Writer<std::fs::File>,
    head: Vec<String>,
    path: PathBuf,
}

/// Writes one CSV per topic into `dir` (`plant.csv`, `servo.csv`, …); returns the files. The
/// columns are the first message's fields; a field another message lacks is left empty.
pub fn export_csv(recording: &Path, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut files: BTreeMap<String, TopicCsv> = BTreeMap::new();
    let mut flat = Flat::default();
    each_message(recording, |topic, data| {
        flat.fill(&parse(topic, data)?);
        if !files.contains_key(topic) {
            let path = dir.join(format!("{}.csv", topic.trim_start_matches('/')));
            let mut writer = csv::Writer::from_path(&path)
                .with_context(|| format!("creating {}", path.display()))?;
            writer
                .write_record(flat.keys())
                .with_context(|| format!("writing {}", path.display()))?;
            let head = flat.keys().to_vec();
            files.insert(topic.to_string(), TopicCsv { writer, head, path });
        }
        let file = files.get_mut(topic).expect("inserted above");
        let written = if flat.keys() == file.head.as_slice() {
            file.writer.write_record(flat.values())
        } else {
            let by_name: BTreeMap<&str, &str> = flat
                .keys()
                .iter()
                .zip(flat.values())
                .map(|(k, v)| (k.as_str(), v.as_str()))
                .collect();
            file.writer.write_record(
                file.head
                    .iter()
                    .map(|h| by_name.get(h.as_str()).copied().unwrap_or("")),
            )
        };
        written.with_context(|| format!("writing {}", file.path.display()))
    })?;
    let mut out = Vec::new();
    for (_, mut file) in files {
        file.writer
            .flush()
            .with_context(|| format!("writing {}", file.path.display()))?;
        out.push(file.path);
    }
    Ok(out)
}

/// The messages of `wanted` topics, at most about `points` of each, evenly spaced: counted in
/// one pass, and only the kept ones parsed in a second.
#[doc(hidden)]
pub fn sample_topics(
    path: &Path,
    wanted: &[&str],
    points: usize,
) -> Result<BTreeMap<String, Vec<serde_json::Value>>> {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    each_message(path, |topic, _| {
        if wanted.contains(&topic) {
            *counts.entry(topic.to_string()).or_default() += 1;
        }
        Ok(())
    })?;
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    each_message(path, |topic, data| {
        let Some(&n) = counts.get(topic) else {
            return Ok(());
        };
        let i = seen.entry(topic.to_string()).or_default();
        let keep = i.is_multiple_of((n / points).max(1));
        *i += 1;
        if keep {
            out.entry(topic.to_string())
                .or_default()
                .push(parse(topic, data)?);
        }
        Ok(())
    })?;
    Ok(out)
}

/// The force, position and dither histories of a recording as a figure (at most about 4000
/// points per series).
pub fn figure(recording: &Path) -> Result<afs_shared::experiments::Figure> {
    use afs_shared::experiments::{Figure, Panel, Series};
    let topics = sample_topics(recording, &["/plant", "/servo"], 4000)?;
    let empty = Vec::new();
    let plant = topics.get("/plant").unwrap_or(&empty);
    let servo = topics.get("/servo").unwrap_or(&empty);
    if plant.is_empty() && servo.is_empty() {
        anyhow::bail!(
            "{} has no /plant or /servo messages; was it recorded with `afs run --record`?",
            recording.display()
        );
    }
    let pick = |msgs: &[serde_json::Value], f: &dyn Fn(&serde_json::Value) -> Option<f64>| {
        msgs.iter()
            .filter_map(|m| Some([m["time_s"].as_f64()?, f(m)?]))
            .collect::<Vec<_>>()
    };
    let line = |label: &str, points: Vec<[f64; 2]>| Series {
        label: label.into(),
        points,
        markers: false,
    };
    let num = |m: &serde_json::Value, k: &str| m[k].as_f64();
    let idx = |m: &serde_json::Value, k: &str, i: usize| m[k][i].as_f64();
    Ok(Figure {
        title: format!("recording {}", recording.display()),
        x_label: "simulated time (s)".into(),
        log_x: false,
        panels: vec![
            Panel {
                x_label: None,
                y_label: "normal force (N)".into(),
                series: vec![
                    line("measured", pick(servo, &|m| num(m, "normal_force_n"))),
                    line("true", pick(plant, &|m| num(m, "normal_force_n"))),
                ],
            },
            Panel {
                x_label: None,
                y_label: "tangential force (N)".into(),
                series: vec![line(
                    "measured",
                    pick(servo, &|m| num(m, "tangential_force_n")),
                )],
            },
            Panel {
                x_label: None,
                y_label: "position along the surface (mm)".into(),
                series: vec![line(
                    "contact u",
                    pick(plant, &|m| num(m, "surface_u_m").map(|u| u * 1e3)),
                )],
            },
            Panel {
                x_label: None,
                y_label: "tip height (mm)".into(),
                series: vec![
                    line("tip", pick(plant, &|m| idx(m, "tip_m", 1).map(|y| y * 1e3))),
                    line(
                        "set-point",
                        pick(servo, &|m| idx(m, "set_point_m", 1).map(|y| y * 1e3)),
                    ),
                ],
            },
            Panel {
                x_label: None,
                y_label: "dither Aω (mm/s)".into(),
                series: vec![line(
                    "commanded",
                    pick(servo, &|m| num(m, "a_omega_m_per_s").map(|a| a * 1e3)),
                )],
            },
        ],
    })
}
/// What `afs record` did: the recording, and the servo stream's sequence numbers as they
/// arrived (every gap counted and placed).
#[derive(Debug, Clone, Serialize)]
pub struct StackRecording {
    /// The file and what it holds.
    pub recording: RecordSummary,
    /// The servo samples' numbers (`seq`).
    pub servo: afs_shared::batch::SeqGaps,
    /// Why it ended: `stopping` (the supervisor said so), `gone` (no node of the stack
    /// left), `interrupted` (Ctrl-C) or `duration`.
    pub ended: String,
    /// Wall time recorded (s).
    pub seconds: f64,
}

impl std::fmt::Display for StackRecording {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "recorded {} ({} messages, {} servo samples, {} missing in {} gaps; ended: {})",
            self.recording.path.display(),
            self.recording.messages.values().sum::<u64>(),
            self.servo.received,
            self.servo.missing,
            self.servo.gaps,
            self.ended
        )
    }
}

/// Records a running stack (every stream, as `afs run --record` does) to `path` until it
/// stops, `duration_s` passes (0: no limit) or `stop` is set.
pub fn record_stack(
    prefix: &str,
    path: &Path,
    duration_s: f64,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<StackRecording> {
    use super::follow::{Ended, Follower};
    use std::sync::atomic::Ordering;
    use std::time::{Duration, Instant};
    if !(duration_s.is_finite() && duration_s >= 0.0) {
        anyhow::bail!(
            "--duration {duration_s} must be a number of seconds ≥ 0 (0: until the stack stops)"
        );
    }
    let mut follower = Follower::open(prefix, "record")?;
    let mut rec = Recorder::start(path)?;
    let mut servo = afs_shared::batch::SeqGaps::default();
    let t0 = Instant::now();
    let ended = loop {
        if stop.load(Ordering::Relaxed) {
            break "interrupted";
        }
        if duration_s > 0.0 && t0.elapsed().as_secs_f64() >= duration_s {
            break "duration";
        }
        std::thread::sleep(Duration::from_millis(5));
        let end = follower.poll(|r| {
            if let Rec::Servo(s) = &r {
                servo.push(s.seq);
            }
            rec.push(r);
        });
        match end {
            Ok(Some(Ended::Stopping)) => {
                // What was published before the supervisor said it stops may still be on its
                // way (across a link, the last batch): keep reading for a moment.
                let t = Instant::now();
                while t.elapsed() < Duration::from_secs(1) {
                    std::thread::sleep(Duration::from_millis(5));
                    let _ = follower.poll(|r| {
                        if let Rec::Servo(s) = &r {
                            servo.push(s.seq);
                        }
                        rec.push(r);
                    });
                }
                break "stopping";
            }
            Ok(Some(Ended::Gone)) => break "gone",
            Ok(None) => {}
            Err(e) => {
                follower.close();
                rec.finish()?;
                return Err(e);
            }
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    follower.close();
    Ok(StackRecording {
        recording: rec.finish()?,
        servo,
        ended: ended.to_string(),
        seconds,
    })
}
