//! Real recordings (SIL runs of the paper's scenario: the simulator's recording, and
//! the controller's own with a second sender on its heartbeat's ID), damaged as a
//! disk, a copy or a kill damages them: each damage refused with its byte offset, and
//! a cut file replayed up to the cut exactly as recorded.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::sync::OnceLock;

use serde_json::json;

use ugv_controller::config::FollowerKind;

use super::scan::{Scanned, scan};
use super::*;
use crate::mission::controller_config;
use crate::record::{MCAP_FILE, RUN_METADATA, RunInfo, topics};
use crate::scenario::{PAPER_SCENARIO, Scenario};
use crate::sil::{Hook, run_sil_recorded, run_sil_with};

const NAME: &str = "run.mcap";

/// Simulated seconds recorded.
const RUN_S: f64 = 6.0;

/// The paper's scenario for [`RUN_S`], with a second sender on the controller's
/// heartbeat (CONTROLLER_HEARTBEAT, 0x80) at 20 Hz from 1.0 s to 1.5 s when asked.
fn scenario(second_sender: bool) -> Scenario {
    let babble = "\n[[faults]]\nkind = \"can_babble\"\nid = 128\nrate_hz = 20.0\nat_s = 1.0\nduration_s = 0.5\n";
    let text = match second_sender {
        true => format!("{PAPER_SCENARIO}{babble}"),
        false => PAPER_SCENARIO.to_owned(),
    };
    let mut sc = Scenario::from_toml(&text, "paper.toml").unwrap();
    sc.sim.time_limit_s = RUN_S;
    sc
}

/// The simulator's recording of a SIL run, made once.
fn sil_recording() -> &'static [u8] {
    static REC: OnceLock<Vec<u8>> = OnceLock::new();
    REC.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let sc = scenario(false);
        let cfg = controller_config(&sc, FollowerKind::Optimal);
        run_sil_recorded(sc, &cfg, |_, _| Hook::Continue, Some(dir.path())).unwrap();
        std::fs::read(dir.path().join(MCAP_FILE)).unwrap()
    })
}

/// The controller's own recording (`ugv-controller run --record`) of a SIL run with a
/// second sender on its heartbeat's ID, made once.
fn controller_recording() -> &'static [u8] {
    static REC: OnceLock<Vec<u8>> = OnceLock::new();
    REC.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let sc = scenario(true);
        let cfg = controller_config(&sc, FollowerKind::Optimal);
        let info = RunInfo::field(
            "the paper's scenario, a second sender on 0x80".to_owned(),
            sc.sim.epoch.unix_ns(),
            "can0".to_owned(),
            sc.gps.sentence_set(),
            sc.gps.baud,
            &cfg,
        )
        .unwrap();
        let mut writer = Some(
            ugv_controller::record::Writer::create(
                Some(dir.path()),
                foxglove::Context::new(),
                info,
            )
            .unwrap(),
        );
        // The binary replans on its planning thread.
        run_sil_with(sc, &cfg, |_, rt| {
            if let Some(w) = writer.take() {
                rt.controller_mut().start_planning_thread().unwrap();
                rt.record_into(w).unwrap();
            }
            Hook::Continue
        })
        .unwrap();
        std::fs::read(dir.path().join(MCAP_FILE)).unwrap()
    })
}

fn read(bytes: &[u8]) -> Result<Recorded, ReplayError> {
    Recorded::parse(NAME, bytes)
}

fn flip(bytes: &[u8], at: u64, bit: u32) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out[(at + u64::from(bit / 8)) as usize] ^= 1 << (bit % 8);
    out
}

/// The chunk that holds the byte at `offset`.
fn chunk_of(file: &Scanned<'_>, offset: u64) -> u64 {
    *file.chunks.iter().rfind(|c| **c < offset).unwrap()
}

/// `bytes` written again by the mcap crate's writer with `options` (its chunk size,
/// its CRCs), the channels' metadata through `channel` (`None`: the channel and its
/// messages left out).
fn rewrite(
    bytes: &[u8],
    options: mcap::WriteOptions,
    channel: impl Fn(&mcap::records::Channel) -> Option<BTreeMap<String, String>>,
) -> Vec<u8> {
    rewrite_with(bytes, options, channel, |_| true, None)
}

/// [`rewrite`], keeping the messages whose log times `keep` keeps, and `extra` (a
/// JSON message: its topic, log time and text) among them in log-time order.
fn rewrite_with(
    bytes: &[u8],
    options: mcap::WriteOptions,
    channel: impl Fn(&mcap::records::Channel) -> Option<BTreeMap<String, String>>,
    keep: impl Fn(u64) -> bool,
    extra: Option<(&str, u64, String)>,
) -> Vec<u8> {
    let file = scan(bytes).unwrap();
    let mut w = options.create(Cursor::new(Vec::new())).unwrap();
    w.write_metadata(&mcap::records::Metadata {
        name: RUN_METADATA.to_owned(),
        metadata: file.run_metadata.clone().unwrap(),
    })
    .unwrap();
    w.attach(&mcap::Attachment {
        log_time: 0,
        create_time: 0,
        name: crate::record::CONFIG_ATTACHMENT.to_owned(),
        media_type: "application/toml".to_owned(),
        data: file.config.clone().unwrap().into(),
    })
    .unwrap();
    let mut ids = BTreeMap::new();
    let mut channels: Vec<_> = file.channels.values().collect();
    channels.sort_by_key(|c| c.id);
    for c in channels {
        if let Some(meta) = channel(c) {
            let id = w
                .add_channel(0, &c.topic, &c.message_encoding, &meta)
                .unwrap();
            ids.insert(c.id, id);
        }
    }
    let mut extra = extra.map(|(topic, log_time, text)| {
        let id = w.add_channel(0, topic, "json", &BTreeMap::new()).unwrap();
        (id, log_time, text)
    });
    let mut write = |channel_id, sequence, log_time, data: &[u8]| {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time,
            publish_time: log_time,
        };
        w.write_to_known_channel(&header, data).unwrap();
    };
    for (sequence, m) in file.messages.iter().enumerate() {
        if let Some((id, log_time, text)) = extra.take_if(|e| e.1 < m.log_time) {
            write(id, u32::MAX, log_time, text.as_bytes());
        }
        if let Some(&channel_id) = ids.get(&m.channel)
            && keep(m.log_time)
        {
            write(channel_id, sequence as u32, m.log_time, &m.data);
        }
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

fn same(c: &mcap::records::Channel) -> Option<BTreeMap<String, String>> {
    Some(c.metadata.clone())
}

fn no_crcs() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(None)
        .calculate_chunk_crcs(false)
        .calculate_data_section_crc(false)
        .calculate_summary_section_crc(false)
}

#[test]
fn whole_recordings_pass_every_check_and_replay_as_recorded() {
    for bytes in [sil_recording(), controller_recording()] {
        let rec = read(bytes).unwrap();
        assert_eq!((rec.truncated.as_deref(), rec.whole_until_ns), (None, None));
        let report = replay(&rec, Tolerance::for_mode(rec.info.mode), None).unwrap();
        assert_eq!(report.divergence, None, "{:?}: {report:?}", rec.info.mode);
        assert_eq!(report.compared_until_s, None);
        let beats = &report.messages["CONTROLLER_HEARTBEAT"];
        assert!(beats.recorded >= 100, "{beats:?}");
        // So does a copy without CRCs (another writer's): nothing to check them by.
        assert!(read(&rewrite(bytes, no_crcs(), same)).is_ok());
    }
}

/// One bit of a message's log time flipped: refused at that message, before any
/// replay (the old reader took it and ticked for 208 days).
#[test]
fn a_flipped_bit_in_a_log_time_is_refused_at_its_message() {
    let bytes = sil_recording();
    let file = scan(bytes).unwrap();
    let m = &file.messages[file.messages.len() / 2];
    // The log time follows the opcode and length (9 bytes), the channel (2) and the
    // sequence (4).
    let time_at = |m: &scan::RawMessage<'_>| m.offset + 9 + 2 + 4;
    // +2^54 ns, 208 days: the chunk's CRC finds it.
    let e = read(&flip(bytes, time_at(m), 54)).unwrap_err();
    let chunk = chunk_of(&file, m.offset);
    assert!(
        matches!(&e, ReplayError::Damaged { offset, what, .. } if *offset == chunk && what.contains("fails its CRC")),
        "{e}"
    );
    assert!(e.is_damaged());
    // Written without CRCs, the times find it, at the message.
    let plain = rewrite(bytes, no_crcs(), same);
    let file = scan(&plain).unwrap();
    let i = file.messages.len() / 2;
    let m = &file.messages[i];
    // A bit that takes it back within the run (after the first message).
    let since_first = m.log_time - file.messages[0].log_time;
    let down = (26..40)
        .find(|b| m.log_time >> b & 1 == 1 && 1 << b < since_first)
        .unwrap();
    let top = 63 - m.log_time.leading_zeros();
    for (bit, why) in [
        (54, "after the message before it (at most 60 s apart)"),
        (down, "before the message before it"),
        (top, "before the run's start"),
    ] {
        let e = read(&flip(&plain, time_at(m), bit)).unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(&e, ReplayError::BadTime { offset, index, .. } if *offset == m.offset && *index == i),
            "bit {bit}: {text}"
        );
        assert!(
            text.starts_with(&format!(
                "{NAME}: damaged at byte {}: message {i} on ",
                m.offset
            )) && text.contains(why),
            "bit {bit}: {text}"
        );
    }
    // The last message, far after the one before it: refused too.
    let last = file.messages.last().unwrap();
    let e = read(&flip(&plain, time_at(last), 54)).unwrap_err();
    assert!(
        matches!(&e, ReplayError::BadTime { offset, .. } if *offset == last.offset),
        "{e}"
    );
}

/// One bit of a record's length flipped: refused at that record (the old reader took
/// the rest of the file for a cut, replayed 2.8 s of 19.3 and said all was as
/// recorded).
#[test]
fn a_flipped_bit_in_a_record_length_is_refused_at_its_record() {
    let bytes = sil_recording();
    let file = scan(bytes).unwrap();
    assert!(file.chunks.len() >= 3, "{} chunks", file.chunks.len());
    let middle = file.chunks[file.chunks.len() / 2];
    let last = *file.chunks.last().unwrap();
    for chunk in [file.chunks[0], middle, last] {
        // The length's 64 bits follow the opcode.
        for bit in [0, 3, 9, 17, 20, 23, 31, 40, 63] {
            let e = read(&flip(bytes, chunk + 1, bit)).unwrap_err();
            assert!(
                matches!(&e, ReplayError::Damaged { offset, .. } if *offset == chunk),
                "chunk at {chunk}, bit {bit}: {e}"
            );
            assert!(
                e.to_string()
                    .starts_with(&format!("{NAME}: damaged at byte {chunk}: ")),
                "{e}"
            );
        }
    }
    // In a file a kill cut inside that chunk: its header's sizes against its length.
    let cut = &bytes[..middle as usize + 100];
    assert!(read(cut).is_ok());
    // (A length made shorter ends the chunk's record inside its header or data, a
    // longer one disagrees with the sizes the header gives.)
    for bit in [0, 9, 20, 40] {
        let e = read(&flip(cut, middle + 1, bit)).unwrap_err();
        assert!(
            matches!(&e, ReplayError::Damaged { offset, .. } if *offset == middle),
            "bit {bit}: {e}"
        );
    }
    // A message's length inside a chunk: the chunk's CRC.
    let m = file.messages.iter().find(|m| m.offset > middle).unwrap();
    let e = read(&flip(bytes, m.offset + 1, 4)).unwrap_err();
    assert!(
        matches!(&e, ReplayError::Damaged { offset, what, .. } if *offset == middle && what.contains("fails its CRC")),
        "{e}"
    );
}

/// One bit flipped in a chunk's records (a laser range, say), or in a chunk's header
/// (which its CRC does not cover, the data section's does).
#[test]
fn a_flipped_bit_in_a_chunk_fails_a_crc() {
    let bytes = sil_recording();
    let file = scan(bytes).unwrap();
    let chunk = file.chunks[1];
    let m = file
        .messages
        .iter()
        .rev()
        .find(|m| m.offset < file.chunks[2])
        .unwrap();
    let e = read(&flip(bytes, m.offset + 30, 5)).unwrap_err();
    assert!(
        matches!(&e, ReplayError::Damaged { offset, what, .. } if *offset == chunk && what.contains("fails its CRC")),
        "{e}"
    );
    // The chunk's last log time (after the opcode and length): its header.
    let e = read(&flip(bytes, chunk + 9 + 8, 2)).unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(&e, ReplayError::Damaged { what, .. } if what.starts_with("the data section (bytes 0 to ")),
        "{text}"
    );
}

/// Seconds of log time the whole records of `bytes` hold.
fn holds_s(bytes: &[u8]) -> f64 {
    let file = scan(bytes).unwrap();
    match (file.messages.first(), file.messages.last()) {
        (Some(first), Some(last)) => (last.log_time - first.log_time) as f64 * 1e-9,
        _ => 0.0,
    }
}

/// A cut file replayed and compared: as recorded, up to the last instant
/// before which it is whole. `None` when the cut left no message on some topic (in
/// the run's first tenth of a second); else whether the replay diverged when
/// compared to the end of what the file holds, as it was before it knew where the
/// file stops being whole.
fn replay_cut(cut: &[u8]) -> Option<bool> {
    let at = cut.len();
    let mut rec = match read(cut) {
        Ok(rec) => rec,
        Err(ReplayError::MissingTopic { .. }) if holds_s(cut) < 0.1 => return None,
        Err(e) => panic!("cut at {at}: {e}"),
    };
    let why = rec.truncated.clone().unwrap();
    assert!(why.starts_with("cut at byte "), "{why}");
    let tol = Tolerance::for_mode(rec.info.mode);
    let report = replay(&rec, tol, None).unwrap();
    assert_eq!(report.divergence, None, "cut at {at} ({why}): {report:#?}");
    let beats = &report.messages["CONTROLLER_HEARTBEAT"];
    assert!(
        beats.matched > 0 && beats.matched == beats.recorded,
        "{beats:?}"
    );
    // Every tick before the instant the comparison stops at.
    let until = report.compared_until_s.unwrap();
    let tick = ugv_controller::control::COMMAND_PERIOD;
    assert!(
        report.replayed_s < until && report.replayed_s >= until - tick - 1e-9,
        "{report:?}"
    );
    rec.whole_until_ns = None;
    let to_the_end = replay(&rec, tol, None).unwrap();
    Some(to_the_end.divergence.is_some())
}

/// The k-th of `n` fractions spread over 0 to 1 at no period of a recording (the
/// golden ratio's multiples).
fn spread(k: usize, len: usize) -> usize {
    (len as f64 * (k as f64 * 0.618_034).fract()) as usize
}

/// The chunk at `chunk` of a cut file made the open chunk a kill leaves: the writer's
/// placeholders for its length and sizes, which it overwrites when it closes it.
fn open(cut: &mut [u8], chunk: usize) {
    let placeholder = u64::MAX.to_le_bytes();
    for (at, len) in [(1, 8), (9, 16), (25, 8), (33, 4), (41, 8)] {
        let value: &[u8] = if at == 9 {
            &[0; 16]
        } else {
            &placeholder[..len]
        };
        cut[chunk + at..chunk + at + len].copy_from_slice(value);
    }
}

/// `bytes` rewritten one message a chunk, so that a cut can leave any message the
/// last whole one, as a kill can (the writer's chunks close at 1 MiB and at every
/// second's flush, wherever in a step that falls), then cut at `n` chunks spread
/// over it: at a chunk's start, in its header, in its records, in an open one (as a
/// kill leaves it: [`open`]). Returns how many
/// cuts replayed, and how many of them diverged compared to the end.
fn replay_cuts_between_messages(bytes: &[u8], n: usize) -> (usize, usize) {
    let one_a_chunk = mcap::WriteOptions::new()
        .compression(None)
        .chunk_size(Some(1));
    let bytes = rewrite(bytes, one_a_chunk, same);
    let chunks = scan(&bytes).unwrap().chunks;
    let (mut replayed, mut diverged) = (0, 0);
    for k in 1..=n {
        let chunk = chunks[spread(k, chunks.len())] as usize;
        let mut cut = bytes[..chunk + [0, 20, 60, 80][k % 4]].to_vec();
        if k % 4 == 3 {
            open(&mut cut, chunk);
        }
        if let Some(d) = replay_cut(&cut) {
            replayed += 1;
            diverged += usize::from(d);
        }
    }
    (replayed, diverged)
}

#[test]
fn a_cut_sil_recording_replays_up_to_the_cut_as_recorded() {
    let (replayed, diverged) = replay_cuts_between_messages(sil_recording(), 40);
    eprintln!(
        "SIL: {replayed} cuts replay as recorded; compared to the end of the file, {diverged} diverged"
    );
    assert!(replayed >= 38, "{replayed}");
    // As the simulator wrote it (1 MiB chunks): cut anywhere.
    let bytes = sil_recording();
    let natural = (1..=4).filter_map(|k| replay_cut(&bytes[..spread(k, bytes.len())]));
    assert!(natural.count() >= 2);
}

#[test]
fn a_cut_controller_recording_replays_up_to_the_cut_as_recorded() {
    let (replayed, diverged) = replay_cuts_between_messages(controller_recording(), 24);
    eprintln!(
        "the controller's own: {replayed} cuts replay as recorded; compared to the end of the file, {diverged} diverged"
    );
    assert!(replayed >= 22, "{replayed}");
}

/// The controller's own recording with everything from 3.0 s to 3.5 s lost, as its
/// recorder loses entries when its queue is full; with the mark the recorder then
/// writes, or without.
fn with_loss(marked: bool) -> Vec<u8> {
    let bytes = controller_recording();
    let epoch = read(bytes).unwrap().info.epoch_unix_ns;
    let (from, to) = (epoch + 3_000_000_000, epoch + 3_500_000_000);
    let mark = json!({ "from": 3.0, "entries": 250 }).to_string();
    let extra = marked.then_some((topics::CONTROLLER_DROPPED, to - 10_000_000, mark));
    rewrite_with(bytes, no_crcs(), same, |t| !(from..to).contains(&t), extra)
}

#[test]
fn entries_the_controllers_recorder_lost_are_said_and_the_replay_compares_up_to_them() {
    let rec = read(&with_loss(true)).unwrap();
    let why = rec.truncated.clone().unwrap();
    assert!(why.contains("lost 250 entries from 3.000 s"), "{why}");
    assert_eq!(
        rec.whole_until_ns,
        Some(rec.info.epoch_unix_ns + 3_000_000_000)
    );
    let report = replay(&rec, Tolerance::for_mode(rec.info.mode), None).unwrap();
    assert_eq!(report.divergence, None, "{report:#?}");
    assert!(
        report.compared_until_s.is_some_and(|t| t <= 3.0),
        "{report:?}"
    );
    assert!(report.replayed_s < 3.0, "{report:?}");
    let beats = &report.messages["CONTROLLER_HEARTBEAT"];
    assert!(
        beats.matched > 100 && beats.matched == beats.recorded,
        "{beats:?}"
    );
    // Unmarked, the same loss is taken for the controller's doing.
    let rec = read(&with_loss(false)).unwrap();
    assert_eq!((rec.truncated.as_ref(), rec.whole_until_ns), (None, None));
    let report = replay(&rec, Tolerance::for_mode(rec.info.mode), None).unwrap();
    assert!(report.divergence.is_some(), "{report:#?}");
}

/// Written in 16 KiB chunks.
fn small_chunks() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(None)
        .chunk_size(Some(16 << 10))
}

#[test]
fn a_recording_without_a_required_channel_is_refused_naming_it() {
    for topic in REQUIRED_TOPICS {
        let bytes = rewrite(sil_recording(), small_chunks(), |c| {
            (c.topic != topic).then(|| c.metadata.clone())
        });
        let e = read(&bytes).unwrap_err();
        assert!(
            matches!(&e, ReplayError::MissingTopic { topic: t, .. } if *t == topic),
            "{topic}: {e}"
        );
        assert!(e.is_damaged());
        assert!(
            e.to_string()
                .starts_with(&format!("{NAME}: no messages on {topic}")),
            "{e}"
        );
    }
}

#[test]
fn laser_metadata_that_is_no_scans_is_refused_naming_the_field() {
    for (key, value, says) in [
        ("angle_min", "NaN", "angle_min = NaN is not a finite number"),
        ("range_max", "inf", "range_max = inf is not a finite number"),
        ("range_min", "-1", "range_min = -1 must not be negative"),
        (
            "scan_time",
            "fast",
            "its metadata scan_time: invalid float literal",
        ),
    ] {
        let bytes = rewrite(sil_recording(), small_chunks(), |c| {
            let mut meta = c.metadata.clone();
            if c.topic == topics::LASER {
                meta.insert(key.to_owned(), value.to_owned());
            }
            Some(meta)
        });
        let e = read(&bytes).unwrap_err();
        assert!(matches!(e, ReplayError::BadChannel { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.starts_with(&format!("{NAME}: the channel {}: ", topics::LASER))
                && text.contains(says),
            "{text}"
        );
    }
}

/// The controller's port hears every frame on its IDs: a second sender's on its
/// heartbeat's are recorded as received, fed to the replayed controller as they were
/// to the recorded one, and not compared as its commands.
#[test]
fn a_second_senders_frames_are_recorded_as_received_and_not_compared() {
    let bytes = controller_recording();
    let file = scan(bytes).unwrap();
    let raw = file
        .channels
        .values()
        .find(|c| c.topic == topics::CAN_RAW)
        .unwrap()
        .id;
    let (mut ours, mut theirs) = (0, 0);
    for m in file.messages.iter().filter(|m| m.channel == raw) {
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if v["id"] != 0x80 {
            continue;
        }
        if v["data"] == "FFFFFFFFFFFFFFFF" {
            assert_eq!((&v["sent"], &v["direction"]), (&false.into(), &"tx".into()));
            theirs += 1;
        } else {
            assert_eq!((&v["sent"], &v["direction"]), (&true.into(), &"rx".into()));
            ours += 1;
        }
    }
    assert!(theirs >= 8 && ours >= 100, "{theirs} babbled, {ours} sent");
    let rec = read(bytes).unwrap();
    let report = replay(&rec, Tolerance::EXACT, None).unwrap();
    assert_eq!(report.divergence, None, "{report:#?}");
    let beats = &report.messages["CONTROLLER_HEARTBEAT"];
    assert_eq!((beats.recorded, beats.matched), (ours, ours), "{beats:?}");
}
