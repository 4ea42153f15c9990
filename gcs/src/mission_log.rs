//! Reading a mission log (`mission.mcap` written by `gcs explore` or `gcs fly`) back: its
//! setup, every drone's camera frames and recorded states, and the last map. A log cut short by
//! a crash reads up to its last whole message.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, bail};
use foxglove::Decode;
use foxglove::messages::{CameraCalibration, CompressedImage, Grid as FoxGrid, PoseInFrame};
use link::camera::{Intrinsics, RgbdFrame};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use nav::grid::{Cell, Grid};
use nav::mission::PlannerConfig;

use crate::record::{DroneState, PlannedGoal, Setup};
use crate::runtime::perception::CameraFrame;

/// A recorded mission, as replay needs it.
#[derive(Debug)]
pub struct MissionLog {
    /// The mission's setup (world, drones, cameras).
    pub setup: Setup,
    /// Camera frames in log order.
    pub frames: Vec<CameraFrame>,
    /// Per drone: (time, state) in time order.
    pub states: Vec<Vec<DroneState>>,
    /// The last recorded 2D map.
    pub grid: Option<Grid>,
    /// The planner's decisions in time order (`/plan`); logs older than the positions and
    /// given-up goals in them give none.
    pub plans: Vec<RecordedPlan>,
    /// Messages read.
    pub messages: usize,
    /// The log ended in an unreadable message (a crash cut it short).
    pub truncated: bool,
}

/// One planner decision as recorded, with what it was made from besides the map.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
pub struct RecordedPlan {
    /// Mission clock, seconds.
    pub t: f64,
    /// Per exploring drone, where it was and its goal.
    pub goals: Vec<PlannedGoal>,
    /// The goals given up by then.
    pub given_up: Vec<[f64; 2]>,
}

impl RecordedPlan {
    /// The mission's planner settings (`mission`, widest radius first) as they stood at this
    /// decision: with the goals given up by then, the goals the drones held and the ways they
    /// faced.
    pub fn planner_configs(&self, mission: &[PlannerConfig]) -> Vec<PlannerConfig> {
        mission
            .iter()
            .map(|c| PlannerConfig {
                blacklist: self.given_up.clone(),
                held: self.goals.iter().map(|g| g.held).collect(),
                headings: self.goals.iter().map(|g| g.heading).collect(),
                ..c.clone()
            })
            .collect()
    }
}

/// Reads what replay needs from a mission log; stops at the first unreadable message (a log cut
/// short by a crash) and says so.
pub fn load(path: &Path) -> anyhow::Result<MissionLog> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    read(&bytes, &path.display().to_string())
}

/// Reads a mission log from its bytes; `origin` names it in errors.
pub fn read(bytes: &[u8], origin: &str) -> anyhow::Result<MissionLog> {
    let not_mcap =
        || format!("{origin} is not an MCAP file (expected a mission.mcap written by gcs explore)");
    if !bytes.starts_with(mcap::MAGIC) {
        bail!(not_mcap());
    }
    let stream = messages(bytes);
    let mut setup = None;
    let mut states: BTreeMap<usize, Vec<DroneState>> = BTreeMap::new();
    let mut grid = None;
    let mut plans = vec![];
    // Per drone: the latest calibration, and colour and depth waiting for their partner.
    let mut calibration: BTreeMap<usize, CameraCalibration> = BTreeMap::new();
    let mut colour: BTreeMap<usize, (u64, Vec<u8>)> = BTreeMap::new();
    let mut depth: BTreeMap<usize, (u64, Vec<u16>, u32, u32)> = BTreeMap::new();
    let mut frames = vec![];
    let mut truths: BTreeMap<(usize, u64), Isometry3<f64>> = BTreeMap::new();
    let (mut messages, mut truncated) = (0, false);
    for m in stream {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                tracing::debug!("log read stops: {e}");
                truncated = true;
                break;
            }
        };
        messages += 1;
        let topic = m.topic.as_str();
        let drone = drone_of(topic);
        match (topic, drone) {
            ("/setup", _) => {
                setup = Some(
                    serde_json::from_slice::<Setup>(&m.data)
                        .context("the log's /setup is not a gcs setup")?,
                );
            }
            ("/map", _) => {
                if let Ok(g) = FoxGrid::decode(&m.data[..]) {
                    grid = grid_of(&g);
                }
            }
            ("/plan", _) => {
                if let Ok(p) = serde_json::from_slice::<RecordedPlan>(&m.data) {
                    plans.push(p);
                }
            }
            (t, Some(k)) if t.ends_with("/state") => {
                if let Ok(s) = serde_json::from_slice::<DroneState>(&m.data) {
                    states.entry(k).or_default().push(s);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/truth") => {
                if let Ok(p) = PoseInFrame::decode(&m.data[..])
                    && let Some(pose) = isometry_of(&p)
                {
                    truths.insert((k, m.log_time), pose);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/calibration") => {
                if let Ok(c) = CameraCalibration::decode(&m.data[..]) {
                    calibration.insert(k, c);
                }
            }
            (t, Some(k)) if t.ends_with("/camera/color") => {
                let Ok(c) = CompressedImage::decode(&m.data[..]) else {
                    continue;
                };
                match image::load_from_memory(&c.data) {
                    Ok(img) => {
                        colour.insert(k, (m.log_time, img.into_rgb8().into_raw()));
                    }
                    Err(e) => tracing::warn!("drone {} colour frame unreadable: {e}", k + 1),
                }
            }
            (t, Some(k)) if t.ends_with("/camera/depth") => {
                let Ok(c) = CompressedImage::decode(&m.data[..]) else {
                    continue;
                };
                match image::load_from_memory(&c.data) {
                    Ok(img) => {
                        let d = img.into_luma16();
                        let (w, h) = d.dimensions();
                        depth.insert(k, (m.log_time, d.into_raw(), w, h));
                    }
                    Err(e) => tracing::warn!("drone {} depth frame unreadable: {e}", k + 1),
                }
            }
            _ => {}
        }
        // A frame is whole once its colour, depth and calibration are in, at one time.
        if let Some(k) = drone
            && let (Some((tc, _)), Some((td, ..)), Some(cal)) =
                (colour.get(&k), depth.get(&k), calibration.get(&k))
            && tc == td
            && cal.k.len() == 9
        {
            let (Some((t, rgb)), Some((_, d, w, h))) = (colour.remove(&k), depth.remove(&k)) else {
                continue;
            };
            if rgb.len() != (w * h * 3) as usize {
                continue;
            }
            frames.push(CameraFrame {
                drone: k,
                stamp: seconds(t),
                frame: Arc::new(RgbdFrame {
                    vehicle: u8::try_from(k).unwrap_or(u8::MAX),
                    stamp: std::time::Duration::from_nanos(t),
                    width: w,
                    height: h,
                    intrinsics: Intrinsics {
                        fx: cal.k[0] as f32,
                        fy: cal.k[4] as f32,
                        cx: cal.k[2] as f32,
                        cy: cal.k[5] as f32,
                    },
                    rgb,
                    depth_mm: d,
                }),
                truth: None,
            });
        }
    }
    let Some(setup) = setup else {
        bail!(
            "{origin} has no /setup message: not a log of gcs explore, or cut before its first second"
        );
    };
    for f in &mut frames {
        f.truth = truths
            .get(&(f.drone, f.frame.stamp.as_nanos() as u64))
            .copied();
    }
    let n = setup.drones.len();
    Ok(MissionLog {
        states: (0..n)
            .map(|k| states.remove(&k).unwrap_or_default())
            .collect(),
        setup,
        frames,
        grid,
        plans,
        messages,
        truncated,
    })
}

/// One planner decision of a log with the map it was made on: for `gcs plan --log`, to make
/// it again and see why a drone got the goal it got, or none.
#[derive(Debug)]
pub struct Decision {
    /// The mission's setup (planner settings).
    pub setup: Setup,
    /// The decision: the first recorded at or after the time asked for.
    pub plan: RecordedPlan,
    /// The map recorded last at or before the decision.
    pub grid: Grid,
    /// When that map was recorded, mission clock, seconds.
    pub grid_t: f64,
}

/// The planner decision recorded first at or after `t` (mission clock, seconds) in a mission
/// log, with its map; `origin` names the log in errors.
pub fn decision_at(bytes: &[u8], origin: &str, t: f64) -> anyhow::Result<Decision> {
    if !bytes.starts_with(mcap::MAGIC) {
        bail!("{origin} is not an MCAP file (expected a mission.mcap written by gcs explore)");
    }
    let (mut setup, mut grid, mut last_plan) = (None, None, None);
    // The recorder writes a decision's map just after it, at its time.
    let mut found = false;
    for m in messages(bytes) {
        let Ok(m) = m else {
            break; // a log cut short: what it has
        };
        match m.topic.as_str() {
            "/setup" => {
                setup = serde_json::from_slice::<Setup>(&m.data).ok();
            }
            "/map" => {
                let (at, same) = map_time(m.log_time, last_plan.as_ref());
                if found && !same {
                    break;
                }
                if let Some(g) = FoxGrid::decode(&m.data[..]).ok().as_ref().and_then(grid_of) {
                    grid = Some((g, at));
                }
                if found {
                    break;
                }
            }
            "/plan" if found => break,
            "/plan" => {
                let Ok(p) = serde_json::from_slice::<RecordedPlan>(&m.data) else {
                    continue;
                };
                found = p.t >= t;
                last_plan = Some(p);
            }
            _ => {}
        }
    }
    let Some(setup) = setup else {
        bail!("{origin} has no /setup message: not a log of gcs explore");
    };
    let Some(plan) = last_plan else {
        bail!("{origin} records no planner decision (/plan): a log of gcs fly, or older than them");
    };
    if plan.t < t {
        bail!(
            "{origin}: no planner decision at or after {t} s; the last is at {:.1} s",
            plan.t
        );
    }
    let Some((grid, grid_t)) = grid else {
        bail!(
            "{origin} records no map before its decision at {:.1} s",
            plan.t
        );
    };
    Ok(Decision {
        setup,
        plan,
        grid,
        grid_t,
    })
}

/// A log time (nanoseconds) in seconds of the mission clock.
fn seconds(log_time: u64) -> f64 {
    log_time as f64 / 1e9
}

/// When a map was recorded (seconds) and whether it is the map of `plan`, the decision read
/// last. The recorder writes a decision's map just after it at its time, so that map takes
/// the decision's own time, of which its nanosecond log time is only the nearest.
fn map_time(log_time: u64, plan: Option<&RecordedPlan>) -> (f64, bool) {
    let at = seconds(log_time);
    match plan {
        Some(p) if (p.t - at).abs() < 1e-3 => (p.t, true),
        _ => (at, false),
    }
}

/// A recorded pose as an isometry (`None` when incomplete or not a rotation).
fn isometry_of(p: &PoseInFrame) -> Option<Isometry3<f64>> {
    let pose = p.pose.as_ref()?;
    let (v, q) = (pose.position.as_ref()?, pose.orientation.as_ref()?);
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = q.norm();
    (norm.is_finite() && (norm - 1.0).abs() < 1e-3 && v.x.is_finite() && v.y.is_finite()).then(
        || {
            Isometry3::from_parts(
                Translation3::new(v.x, v.y, v.z),
                UnitQuaternion::from_quaternion(q),
            )
        },
    )
}

/// The drone index of a `/droneK/...` topic.
fn drone_of(topic: &str) -> Option<usize> {
    let rest = topic.strip_prefix("/drone")?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse::<usize>().ok()?.checked_sub(1)
}

/// A recorded `foxglove.Grid` (int8 occupancy, as the recorder writes it) as a map.
fn grid_of(g: &FoxGrid) -> Option<Grid> {
    let w = g.column_count as usize;
    let res = g.cell_size.as_ref()?.x;
    if w == 0 || g.cell_stride != 1 || g.row_stride as usize != w || !res.is_finite() || res <= 0.0
    {
        return None;
    }
    let h = g.data.len() / w;
    let o = g.pose.as_ref()?.position.as_ref()?;
    let mut grid = Grid::new(w, h, res, [o.x, o.y], Cell::Unknown);
    for y in 0..h {
        for x in 0..w {
            let cell = match g.data[y * w + x] as i8 {
                0 => Cell::Free,
                100 => Cell::Occupied,
                _ => Cell::Unknown,
            };
            grid.set((x, y), cell);
        }
    }
    Some(grid)
}

/// The largest record the reader takes (compressed or not). A mission log's largest records are
/// its chunks (about a megabyte); a record that claims more is a corrupt or hostile file.
const MAX_RECORD_BYTES: usize = 64 << 20;

/// One message of a log: its topic, log time and bytes.
#[derive(Debug)]
struct Message {
    topic: String,
    log_time: u64,
    data: Vec<u8>,
}

/// The messages of an MCAP file in log order, read with bounded memory and without trusting any
/// length in the file: records larger than [`MAX_RECORD_BYTES`] are refused, chunks are
/// decompressed here into at most that much, and the only records parsed — channels and
/// messages — are parsed with every length checked against the record. (The `mcap` crate's own
/// record parser trusts string lengths — a 94-byte file made it reserve 3.8 GB — and its reader
/// of uncompressed chunks overflows on a record longer than its chunk: both found by fuzzing.
/// Only its framing of top-level records is used.)
fn messages(bytes: &[u8]) -> impl Iterator<Item = anyhow::Result<Message>> + '_ {
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(MAX_RECORD_BYTES)
            .with_emit_chunks(true),
    );
    let mut rest = bytes;
    let mut topics: BTreeMap<u16, String> = BTreeMap::new();
    let mut pending: std::collections::VecDeque<Message> = std::collections::VecDeque::new();
    let mut failed = false;
    let mut next = move || -> Option<anyhow::Result<Message>> {
        loop {
            if let Some(m) = pending.pop_front() {
                return Some(Ok(m));
            }
            let event = match reader.next_event()? {
                Ok(e) => e,
                Err(e) => return Some(Err(anyhow::anyhow!("{e}"))),
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                }
                LinearReadEvent::Record { opcode, data } => {
                    let done = if opcode == mcap::records::op::CHUNK {
                        chunk_records(data).and_then(|records| {
                            let mut records = &records[..];
                            while !records.is_empty() {
                                let (op, body) = record(&mut records).ok_or_else(|| {
                                    anyhow::anyhow!("a malformed record in a chunk")
                                })?;
                                take_record(op, body, &mut topics, &mut pending)?;
                            }
                            Ok(())
                        })
                    } else {
                        take_record(opcode, data, &mut topics, &mut pending)
                    };
                    if let Err(e) = done {
                        return Some(Err(e));
                    }
                }
            }
        }
    };
    // The first error ends the stream.
    std::iter::from_fn(move || {
        if failed {
            return None;
        }
        let item = next();
        failed = matches!(item, Some(Err(_)));
        item
    })
}

/// Keeps what a record says that the reader needs: a channel's topic, or a message.
fn take_record(
    opcode: u8,
    body: &[u8],
    topics: &mut BTreeMap<u16, String>,
    out: &mut std::collections::VecDeque<Message>,
) -> anyhow::Result<()> {
    match opcode {
        mcap::records::op::CHANNEL => {
            let (id, topic) =
                channel_topic(body).ok_or_else(|| anyhow::anyhow!("a malformed channel record"))?;
            topics.insert(id, topic);
        }
        mcap::records::op::MESSAGE => {
            let (channel, log_time, payload) =
                message_parts(body).ok_or_else(|| anyhow::anyhow!("a malformed message record"))?;
            let topic = topics.get(&channel).ok_or_else(|| {
                anyhow::anyhow!("a message on channel {channel}, which was never declared")
            })?;
            out.push_back(Message {
                topic: topic.clone(),
                log_time,
                data: payload.to_vec(),
            });
        }
        _ => {}
    }
    Ok(())
}

/// One record (opcode u8, length u64, body) from the front of `bytes`.
fn record<'a>(bytes: &mut &'a [u8]) -> Option<(u8, &'a [u8])> {
    let opcode = *take(bytes, 1)?.first()?;
    let len = usize::try_from(take_u64(bytes)?).ok()?;
    Some((opcode, take(bytes, len)?))
}

/// A chunk's records, decompressed (MCAP: start and end time u64, uncompressed size u64, CRC u32,
/// compression as u32 length + text, records as u64 length + bytes).
fn chunk_records(mut chunk: &[u8]) -> anyhow::Result<std::borrow::Cow<'_, [u8]>> {
    let malformed = || anyhow::anyhow!("a malformed chunk");
    take(&mut chunk, 16).ok_or_else(malformed)?;
    let size = take_u64(&mut chunk).ok_or_else(malformed)?;
    take(&mut chunk, 4).ok_or_else(malformed)?;
    let name_len = take(&mut chunk, 4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .ok_or_else(malformed)?;
    let compression = take(&mut chunk, usize::try_from(name_len)?).ok_or_else(malformed)?;
    let len = usize::try_from(take_u64(&mut chunk).ok_or_else(malformed)?)?;
    let records = take(&mut chunk, len).ok_or_else(malformed)?;
    let size = usize::try_from(size)?;
    if size > MAX_RECORD_BYTES {
        bail!("a chunk of {size} bytes uncompressed (at most {MAX_RECORD_BYTES})");
    }
    match compression {
        b"" => Ok(std::borrow::Cow::Borrowed(records)),
        b"zstd" => {
            let out = zstd::bulk::decompress(records, size)
                .map_err(|e| anyhow::anyhow!("a chunk that does not decompress: {e}"))?;
            if out.len() != size {
                bail!("a chunk of {} bytes where {size} were declared", out.len());
            }
            Ok(std::borrow::Cow::Owned(out))
        }
        other => bail!(
            "chunks compressed with {:?} (mission logs use zstd)",
            String::from_utf8_lossy(other)
        ),
    }
}

/// Takes `n` bytes from the front of `bytes`.
fn take<'a>(bytes: &mut &'a [u8], n: usize) -> Option<&'a [u8]> {
    if bytes.len() < n {
        return None;
    }
    let (head, tail) = bytes.split_at(n);
    *bytes = tail;
    Some(head)
}

fn take_u16(bytes: &mut &[u8]) -> Option<u16> {
    take(bytes, 2).map(|b| u16::from_le_bytes([b[0], b[1]]))
}

fn take_u64(bytes: &mut &[u8]) -> Option<u64> {
    take(bytes, 8)
        .and_then(|b| b.try_into().ok())
        .map(u64::from_le_bytes)
}

/// A channel record's id and topic (MCAP: id u16, schema id u16, topic as u32 length + UTF-8).
fn channel_topic(mut record: &[u8]) -> Option<(u16, String)> {
    let id = take_u16(&mut record)?;
    take_u16(&mut record)?;
    let len = take(&mut record, 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))?;
    let topic = take(&mut record, usize::try_from(len).ok()?)?;
    Some((id, String::from_utf8(topic.to_vec()).ok()?))
}

/// A message record's channel, log time and payload (MCAP: channel u16, sequence u32, log time
/// u64, publish time u64, payload).
fn message_parts(mut record: &[u8]) -> Option<(u16, u64, &[u8])> {
    let channel = take_u16(&mut record)?;
    take(&mut record, 4)?;
    let log_time = take_u64(&mut record)?;
    take_u64(&mut record)?;
    Some((channel, log_time, record))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drone_topics_name_their_drone() {
        assert_eq!(drone_of("/drone1/camera/color"), Some(0));
        assert_eq!(drone_of("/drone12/state"), Some(11));
        assert_eq!(drone_of("/drone0/state"), None);
        assert_eq!(drone_of("/map"), None);
    }

    #[test]
    fn a_recorded_decision_plans_with_what_it_had_given_up_and_the_goals_the_drones_held() {
        // As written on `/plan`: drone 2 held no goal and faced no known way, and a log from
        // before held goals and headings has neither.
        let plan: RecordedPlan = serde_json::from_str(
            r#"{"t": 12.0, "given_up": [[1.0, 2.0]], "goals": [
                {"drone": 1, "position": [0.5, 0.5], "held": [3.0, 4.0], "heading": 1.5,
                 "goal": [3.1, 4.0]},
                {"drone": 2, "position": null, "goal": null}]}"#,
        )
        .expect("a recorded plan");
        let mission = [0.45, 0.25].map(|robot_radius_m| PlannerConfig {
            robot_radius_m,
            hold_margin_m: 0.7,
            ..PlannerConfig::default()
        });
        let configs = plan.planner_configs(&mission);
        assert_eq!(configs.len(), 2);
        for (c, m) in configs.iter().zip(&mission) {
            assert_eq!(c.robot_radius_m, m.robot_radius_m);
            assert_eq!(c.hold_margin_m, 0.7);
            assert_eq!(c.blacklist, vec![[1.0, 2.0]]);
            assert_eq!(c.held, vec![Some([3.0, 4.0]), None]);
            assert_eq!(c.headings, vec![Some(1.5), None]);
        }
    }

    #[test]
    fn the_map_written_with_a_decision_is_dated_at_the_decision_to_the_last_bit() {
        // 20.29 s once came back as 20.290000000000003 from its log time.
        for k in 0..200_000u64 {
            let t = k as f64 * 0.01;
            let plan = RecordedPlan {
                t,
                goals: vec![],
                given_up: vec![],
            };
            for log_time in [crate::record::log_time(t), (t * 1e9) as u64] {
                assert_eq!(map_time(log_time, Some(&plan)), (t, true), "{t} s");
            }
        }
        // A map from before the decision keeps its own time.
        let plan = RecordedPlan {
            t: 20.29,
            goals: vec![],
            given_up: vec![],
        };
        assert_eq!(map_time(19_500_000_000, Some(&plan)), (19.5, false));
        assert_eq!(map_time(19_500_000_000, None), (19.5, false));
    }

    #[test]
    fn what_is_not_a_mission_log_says_so() {
        let e = format!("{:#}", read(b"hello", "x.mcap").expect_err("not MCAP"));
        assert!(e.contains("x.mcap is not an MCAP file"), "{e}");
        let e = format!("{:#}", read(mcap::MAGIC, "y.mcap").expect_err("no setup"));
        assert!(e.contains("y.mcap"), "{e}");
    }

    /// An MCAP file with `n` messages on "/a", in zstd chunks.
    fn small_log(n: u64) -> Vec<u8> {
        let mut out = std::io::Cursor::new(vec![]);
        {
            let mut w = mcap::WriteOptions::new()
                .compression(Some(mcap::Compression::Zstd))
                .chunk_size(Some(256))
                .create(&mut out)
                .expect("writer");
            let channel = w
                .add_channel(0, "/a", "json", &BTreeMap::new())
                .expect("channel");
            for i in 0..n {
                let header = mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: i as u32,
                    log_time: 1000 + i,
                    publish_time: 1000 + i,
                };
                w.write_to_known_channel(&header, format!("{{\"i\":{i}}}").as_bytes())
                    .expect("message");
            }
            w.finish().expect("finish");
        }
        out.into_inner()
    }

    #[test]
    fn messages_read_back_in_order_and_a_cut_log_up_to_its_last_whole_chunk() {
        let log = small_log(40);
        let all: Vec<Message> = messages(&log).map(|m| m.expect("readable")).collect();
        assert_eq!(all.len(), 40);
        for (i, m) in all.iter().enumerate() {
            assert_eq!(m.topic, "/a");
            assert_eq!(m.log_time, 1000 + i as u64);
            assert_eq!(m.data, format!("{{\"i\":{i}}}").as_bytes());
        }
        let cut = &log[..log.len() / 2];
        let read: Vec<_> = messages(cut).collect();
        let whole = read.iter().take_while(|m| m.is_ok()).count();
        assert!(whole > 0 && whole < 40, "{whole}");
        assert!(
            read.last().is_some_and(Result::is_err),
            "the cut must be reported"
        );
    }

    #[test]
    fn the_fuzzers_findings_are_clean_errors() {
        for (name, bytes) in [
            (
                "4 GB header string (out of memory in mcap 0.26)",
                &include_bytes!("../tests/fixtures/fuzz-mission-log-4gb-string.mcap")[..],
            ),
            (
                "record longer than its uncompressed chunk (overflow panic in mcap 0.26)",
                &include_bytes!("../tests/fixtures/fuzz-mission-log-chunk-overflow.mcap")[..],
            ),
        ] {
            assert!(read(bytes, name).is_err(), "{name}");
        }
    }

    #[test]
    fn lying_lengths_are_errors_not_allocations() {
        // A channel record whose topic claims 4 GB (the fuzzer's finding was the same lie in a
        // header's profile string, which this reader never parses).
        let mut log = mcap::MAGIC.to_vec();
        let body = [
            &1u16.to_le_bytes()[..],
            &0u16.to_le_bytes(),
            &0xF000_0000u32.to_le_bytes(),
            b"/a",
        ]
        .concat();
        log.push(mcap::records::op::CHANNEL);
        log.extend((body.len() as u64).to_le_bytes());
        log.extend(&body);
        let e = messages(&log)
            .next()
            .expect("an item")
            .expect_err("refused");
        assert!(e.to_string().contains("malformed channel"), "{e}");
        // The fuzzer's file: a header whose profile string claims 4 GB.
        let mut log = mcap::MAGIC.to_vec();
        let body = [&0xF000_0000u32.to_le_bytes()[..], b"x"].concat();
        log.push(mcap::records::op::HEADER);
        log.extend((body.len() as u64).to_le_bytes());
        log.extend(&body);
        assert!(read(&log, "evil.mcap").is_err());
        // A record claiming 1 TB.
        let mut log = mcap::MAGIC.to_vec();
        log.push(mcap::records::op::CHUNK);
        log.extend((1u64 << 40).to_le_bytes());
        assert!(messages(&log).any(|m| m.is_err()));
    }
}
