//! The recording's MCAP file, its records laid out by hand (the MCAP format,
//! mcap.dev/spec): a [`foxglove::Sink`] on the recording's context, so the channels log
//! to it as to any sink. Messages go into an uncompressed chunk on the logging thread;
//! a closed chunk is CRC'd in one pass and written on the file's own thread; the schemas and channels where first used, in the chunk; the run's
//! metadata and attachment before the first chunk; the summary section (schemas,
//! channels, statistics, chunk, attachment and metadata indexes, with their offsets) and
//! the footer at the end, the data section's and the summary's CRCs included. The
//! Foxglove SDK's own MCAP sink wrote the same records through the mcap crate's writer
//! at some 2,650 instructions a message (a CRC writer under every small write of each
//! header); this writes a message's 31-byte header into the chunk buffer directly.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::thread::JoinHandle;

use firmware_bridge::sync::lock;
use foxglove::{ChannelId, FoxgloveError, Metadata, RawChannel, Sink, SinkId};

/// The MCAP magic, at the start and the end of the file.
const MAGIC: &[u8] = b"\x89MCAP0\r\n";
/// The library named in the header.
const LIBRARY: &str = concat!("ugv-hil ", env!("CARGO_PKG_VERSION"));

/// Record opcodes.
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const ATTACHMENT: u8 = 0x09;
    pub const ATTACHMENT_INDEX: u8 = 0x0A;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// A record's body as it is built: the MCAP primitive types, little-endian.
#[derive(Default)]
struct Body(Vec<u8>);

impl Body {
    fn u8(mut self, v: u8) -> Body {
        self.0.push(v);
        self
    }
    fn u16(mut self, v: u16) -> Body {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u32(mut self, v: u32) -> Body {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u64(mut self, v: u64) -> Body {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A string or byte array with a u32 length.
    fn bytes32(self, v: &[u8]) -> Body {
        let mut b = self.u32(v.len() as u32);
        b.0.extend_from_slice(v);
        b
    }
    fn str(self, v: &str) -> Body {
        self.bytes32(v.as_bytes())
    }
    /// A byte array with a u64 length.
    fn bytes64(self, v: &[u8]) -> Body {
        let mut b = self.u64(v.len() as u64);
        b.0.extend_from_slice(v);
        b
    }
    /// A map of strings.
    fn strings(self, map: &BTreeMap<String, String>) -> Body {
        let entries = map
            .iter()
            .fold(Body::default(), |b, (k, v)| b.str(k).str(v));
        self.bytes32(&entries.0)
    }
    /// The record: opcode, length, body.
    fn record(self, opcode: u8) -> Vec<u8> {
        let mut out = Vec::with_capacity(9 + self.0.len());
        out.push(opcode);
        out.extend_from_slice(&(self.0.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.0);
        out
    }
}

/// The chunk being filled.
#[derive(Default)]
struct Chunk {
    records: Vec<u8>,
    start: u64,
    end: u64,
    /// Per channel (by MCAP id), each message's log time and offset in `records`.
    index: Vec<Vec<(u64, u64)>>,
    messages: usize,
}

impl Chunk {
    /// Emptied, its buffers kept (a chunk's grows to the chunk size once).
    fn cleared(mut self) -> Chunk {
        self.records.clear();
        self.index.iter_mut().for_each(Vec::clear);
        self.messages = 0;
        self
    }
}

/// What the summary section needs of the messages, gathered as they are logged.
#[derive(Default)]
struct Messages {
    schemas: Vec<u8>,
    channels: Vec<u8>,
    messages: u64,
    schema_count: u16,
    channel_count: u32,
    start: Option<u64>,
    end: u64,
    /// Messages per channel, by MCAP id.
    per_channel: Vec<u64>,
}

/// What the writer thread is asked to do, in order.
enum Job {
    /// Write a closed chunk and its message indexes.
    Chunk(Chunk),
    /// Write a record outside the chunks (`opcode` names its index: metadata or
    /// attachment); its index is its offset and length, then `tail`.
    Outside {
        record: Vec<u8>,
        opcode: u8,
        tail: Body,
    },
    /// Hand what was written on.
    Flush,
    /// Write the data section's end, the summary section and the footer.
    Finish(Messages),
}

/// The file as the writer thread writes it: everything that needs a record's offset.
struct FileOut<W: Write> {
    out: W,
    /// Bytes written to `out`.
    pos: u64,
    /// Over the data section, from the magic on.
    data_crc: crc32fast::Hasher,
    chunk_indexes: Vec<u8>,
    attachment_indexes: Vec<u8>,
    metadata_indexes: Vec<u8>,
    chunk_count: u32,
    attachment_count: u32,
    metadata_count: u32,
}

impl<W: Write> FileOut<W> {
    /// The file's magic and header on `out`.
    fn start(out: W) -> std::io::Result<FileOut<W>> {
        let mut f = FileOut {
            out,
            pos: 0,
            data_crc: crc32fast::Hasher::new(),
            chunk_indexes: Vec::new(),
            attachment_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            chunk_count: 0,
            attachment_count: 0,
            metadata_count: 0,
        };
        f.write(MAGIC)?;
        f.write(&Body::default().str("").str(LIBRARY).record(op::HEADER))?;
        Ok(f)
    }

    fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.out.write_all(bytes)?;
        self.data_crc.update(bytes);
        self.pos += bytes.len() as u64;
        Ok(())
    }

    /// Write chunk `c` and its message indexes. The chunk's records are CRC'd once:
    /// the data section's CRC takes theirs.
    fn chunk(&mut self, c: &Chunk) -> std::io::Result<()> {
        let chunk_start = self.pos;
        let mut crc = crc32fast::Hasher::new();
        crc.update(&c.records);
        let size = c.records.len() as u64;
        let mut head = Body::default()
            .u64(c.start)
            .u64(c.end)
            .u64(size)
            .u32(crc.clone().finalize())
            .str("")
            .u64(size)
            .record(op::CHUNK);
        // The record's length counts the records that follow its head.
        let length = head.len() as u64 - 9 + size;
        head[1..9].copy_from_slice(&length.to_le_bytes());
        self.write(&head)?;
        self.out.write_all(&c.records)?;
        self.data_crc.combine(&crc);
        self.pos += size;
        let index_start = self.pos;
        let mut offsets = Body::default();
        for (id, entries) in c.index.iter().enumerate().filter(|(_, e)| !e.is_empty()) {
            offsets = offsets.u16(id as u16).u64(self.pos);
            let list = entries
                .iter()
                .fold(Body::default(), |b, &(t, o)| b.u64(t).u64(o));
            let index = Body::default()
                .u16(id as u16)
                .bytes32(&list.0)
                .record(op::MESSAGE_INDEX);
            self.write(&index)?;
        }
        let entry = Body::default()
            .u64(c.start)
            .u64(c.end)
            .u64(chunk_start)
            .u64(index_start - chunk_start)
            .bytes32(&offsets.0)
            .u64(self.pos - index_start)
            .str("")
            .u64(size)
            .u64(size)
            .record(op::CHUNK_INDEX);
        self.chunk_indexes.extend_from_slice(&entry);
        self.chunk_count += 1;
        Ok(())
    }

    /// A metadata or attachment record, and its index.
    fn outside(&mut self, record: &[u8], opcode: u8, tail: Body) -> std::io::Result<()> {
        let mut index = Body::default().u64(self.pos).u64(record.len() as u64);
        index.0.extend_from_slice(&tail.0);
        self.write(record)?;
        let (list, count) = if opcode == op::METADATA_INDEX {
            (&mut self.metadata_indexes, &mut self.metadata_count)
        } else {
            (&mut self.attachment_indexes, &mut self.attachment_count)
        };
        list.extend_from_slice(&index.record(opcode));
        *count += 1;
        Ok(())
    }

    /// The data section's end, the summary section and the footer.
    fn finish(mut self, m: Messages) -> std::io::Result<W> {
        let data_end = Body::default()
            .u32(self.data_crc.clone().finalize())
            .record(op::DATA_END);
        self.write(&data_end)?;
        let stats = (m.per_channel.iter().enumerate())
            .fold(Body::default(), |b, (id, &n)| b.u16(id as u16).u64(n));
        let statistics = Body::default()
            .u64(m.messages)
            .u16(m.schema_count)
            .u32(m.channel_count)
            .u32(self.attachment_count)
            .u32(self.metadata_count)
            .u32(self.chunk_count)
            .u64(m.start.unwrap_or(0))
            .u64(m.end)
            .bytes32(&stats.0)
            .record(op::STATISTICS);
        let summary_start = self.pos;
        let mut crc = crc32fast::Hasher::new();
        let mut offsets = Vec::new();
        let groups = [
            (op::SCHEMA, &m.schemas),
            (op::CHANNEL, &m.channels),
            (op::STATISTICS, &statistics),
            (op::CHUNK_INDEX, &self.chunk_indexes),
            (op::ATTACHMENT_INDEX, &self.attachment_indexes),
            (op::METADATA_INDEX, &self.metadata_indexes),
        ];
        let mut at = summary_start;
        for (opcode, bytes) in groups.into_iter().filter(|(_, b)| !b.is_empty()) {
            self.out.write_all(bytes)?;
            crc.update(bytes);
            let offset = Body::default()
                .u8(opcode)
                .u64(at)
                .u64(bytes.len() as u64)
                .record(op::SUMMARY_OFFSET);
            offsets.extend_from_slice(&offset);
            at += bytes.len() as u64;
        }
        self.out.write_all(&offsets)?;
        crc.update(&offsets);
        // The summary's CRC runs on into the footer, up to the CRC itself.
        let mut footer = Body::default()
            .u64(summary_start)
            .u64(at)
            .u32(0)
            .record(op::FOOTER);
        let crc_at = footer.len() - 4;
        crc.update(&footer[..crc_at]);
        footer[crc_at..].copy_from_slice(&crc.finalize().to_le_bytes());
        self.out.write_all(&footer)?;
        self.out.write_all(MAGIC)?;
        self.out.flush()?;
        Ok(self.out)
    }
}

/// The writer thread: the jobs in order, then the file. Emptied chunks go back on
/// `spare`.
fn write_jobs<W: Write>(
    mut file: FileOut<W>,
    jobs: Receiver<Job>,
    spare: Sender<Chunk>,
) -> std::io::Result<W> {
    while let Ok(job) = jobs.recv() {
        match job {
            Job::Finish(m) => return file.finish(m),
            Job::Chunk(c) => {
                file.chunk(&c)?;
                // None waiting any more: the file is being closed.
                let _ = spare.send(c.cleared());
            }
            Job::Outside {
                record,
                opcode,
                tail,
            } => file.outside(&record, opcode, tail)?,
            Job::Flush => file.out.flush()?,
        }
    }
    Err(closed())
}

/// Chunks closed and not yet written that may wait for the writer thread before a
/// message waits (a few seconds of a run's recording).
const QUEUED_JOBS: usize = 8;

/// The messages' side of the file, on the thread that logs them.
struct Logging {
    chunk: Chunk,
    chunk_size: usize,
    /// The context's channel ids, in the order of their MCAP ids (a run has about ten).
    channels: Vec<ChannelId>,
    schemas: HashMap<(String, String), u16>,
    /// The last sequence number per channel, by MCAP id.
    sequences: Vec<u32>,
    summary: Messages,
    jobs: SyncSender<Job>,
    spare: Receiver<Chunk>,
}

impl Logging {
    /// The MCAP id of `channel`, its schema and channel records written into the chunk
    /// (and kept for the summary) when first seen.
    fn channel_id(&mut self, channel: &RawChannel) -> u16 {
        if let Some(id) = self.channels.iter().position(|&c| c == channel.id()) {
            return id as u16;
        }
        let schema_id = channel.schema().map_or(0, |s| {
            let key = (s.name.clone(), s.encoding.clone());
            if let Some(&id) = self.schemas.get(&key) {
                return id;
            }
            let id = self.schemas.len() as u16 + 1;
            self.schemas.insert(key, id);
            let record = Body::default()
                .u16(id)
                .str(&s.name)
                .str(&s.encoding)
                .bytes32(&s.data)
                .record(op::SCHEMA);
            self.chunk.records.extend_from_slice(&record);
            self.summary.schemas.extend_from_slice(&record);
            self.summary.schema_count += 1;
            id
        });
        let id = self.channels.len() as u16;
        self.channels.push(channel.id());
        self.sequences.push(0);
        self.summary.per_channel.push(0);
        self.summary.channel_count += 1;
        let record = Body::default()
            .u16(id)
            .u16(schema_id)
            .str(channel.topic())
            .str(channel.message_encoding())
            .strings(channel.metadata())
            .record(op::CHANNEL);
        self.chunk.records.extend_from_slice(&record);
        self.summary.channels.extend_from_slice(&record);
        id
    }

    /// A message's header and bytes into the chunk; the chunk handed to the writer
    /// thread once full. False when the writer thread has stopped.
    fn message(&mut self, channel: &RawChannel, msg: &[u8], time: u64) -> bool {
        let id = self.channel_id(channel);
        let k = usize::from(id);
        self.sequences[k] += 1;
        let c = &mut self.chunk;
        if c.messages == 0 {
            (c.start, c.end) = (time, time);
        }
        (c.start, c.end) = (c.start.min(time), c.end.max(time));
        c.messages += 1;
        if c.index.len() <= k {
            c.index.resize_with(k + 1, Vec::new);
        }
        c.index[k].push((time, c.records.len() as u64));
        let mut header = [0u8; 31];
        header[0] = op::MESSAGE;
        header[1..9].copy_from_slice(&(22 + msg.len() as u64).to_le_bytes());
        header[9..11].copy_from_slice(&id.to_le_bytes());
        header[11..15].copy_from_slice(&self.sequences[k].to_le_bytes());
        header[15..23].copy_from_slice(&time.to_le_bytes());
        header[23..31].copy_from_slice(&time.to_le_bytes());
        c.records.extend_from_slice(&header);
        c.records.extend_from_slice(msg);
        let s = &mut self.summary;
        s.messages += 1;
        s.start = Some(s.start.map_or(time, |t| t.min(time)));
        s.end = s.end.max(time);
        s.per_channel[k] += 1;
        self.chunk.records.len() < self.chunk_size || self.close_chunk()
    }

    /// Hand the chunk (when it holds anything) to the writer thread and take an
    /// emptied one. False when the writer thread has stopped.
    fn close_chunk(&mut self) -> bool {
        if self.chunk.records.is_empty() {
            return true;
        }
        let next = self.spare.try_recv().unwrap_or_default();
        let full = std::mem::replace(&mut self.chunk, next);
        self.jobs.send(Job::Chunk(full)).is_ok()
    }

    /// A job after the chunk being filled. False when the writer thread has stopped.
    fn send(&mut self, job: Job) -> bool {
        self.close_chunk() && self.jobs.send(job).is_ok()
    }
}

/// An MCAP file being written, as a sink of the recording's context: messages are
/// gathered into chunks on the thread that logs them, and the chunks written (CRC'd,
/// indexed) on a thread of the file's own, so that a second's recording never waits
/// for the disk on the logging thread (in an emulated VM, writing a chunk of half a
/// megabyte at once held a real-time simulator's tick 0.3 s).
pub struct McapFile<W: Write + Send + 'static> {
    id: SinkId,
    /// None once closed, or after an error (the first kept in `error`).
    logging: Mutex<Option<Logging>>,
    writer: Mutex<Option<JoinHandle<std::io::Result<W>>>>,
    error: Mutex<Option<std::io::Error>>,
}

impl<W: Write + Send + 'static> McapFile<W> {
    /// Start the file on `out`: its magic and header. Chunks close once they hold
    /// `chunk_size` bytes (or at [`McapFile::flush`]).
    pub fn create(out: W, chunk_size: usize) -> std::io::Result<McapFile<W>> {
        let file = FileOut::start(out)?;
        let (jobs, queue) = std::sync::mpsc::sync_channel(QUEUED_JOBS);
        let (give_back, spare) = std::sync::mpsc::channel();
        let writer = std::thread::Builder::new()
            .name("mcap-writer".to_owned())
            .spawn(move || write_jobs(file, queue, give_back))?;
        let logging = Logging {
            chunk: Chunk::default(),
            chunk_size,
            channels: Vec::new(),
            schemas: HashMap::new(),
            sequences: Vec::new(),
            summary: Messages::default(),
            jobs,
            spare,
        };
        Ok(McapFile {
            id: SinkId::next(),
            logging: Mutex::new(Some(logging)),
            writer: Mutex::new(Some(writer)),
            error: Mutex::new(None),
        })
    }

    /// Run `f` on the open file; when it finds the writer thread stopped, the file is
    /// closed for good and the thread's error kept for [`McapFile::close`].
    fn with(&self, f: impl FnOnce(&mut Logging) -> bool) -> std::io::Result<()> {
        let mut guard = lock(&self.logging);
        let logging = guard.as_mut().ok_or_else(|| self.failure())?;
        if f(logging) {
            return Ok(());
        }
        *guard = None;
        let error = match lock(&self.writer).take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            Some(Err(_)) => std::io::Error::other("the MCAP writer thread panicked"),
            _ => closed(),
        };
        let copy = std::io::Error::new(error.kind(), error.to_string());
        lock(&self.error).get_or_insert(error);
        Err(copy)
    }

    /// The error that closed the file, as a copy.
    fn failure(&self) -> std::io::Error {
        lock(&self.error)
            .as_ref()
            .map_or_else(closed, |e| std::io::Error::new(e.kind(), e.to_string()))
    }

    /// A metadata record named `name`.
    pub fn metadata(&self, name: &str, map: &BTreeMap<String, String>) -> std::io::Result<()> {
        let record = Body::default().str(name).strings(map).record(op::METADATA);
        let tail = Body::default().str(name);
        self.with(|f| {
            f.send(Job::Outside {
                record,
                opcode: op::METADATA_INDEX,
                tail,
            })
        })
    }

    /// An attachment: `data` named `name`, of `media_type`, at `time` (ns).
    pub fn attach(
        &self,
        name: &str,
        media_type: &str,
        time: u64,
        data: &[u8],
    ) -> std::io::Result<()> {
        let mut body = Body::default()
            .u64(time)
            .u64(time)
            .str(name)
            .str(media_type)
            .bytes64(data);
        let crc = crc32fast::hash(&body.0);
        body = body.u32(crc);
        let record = body.record(op::ATTACHMENT);
        let tail = Body::default()
            .u64(time)
            .u64(time)
            .u64(data.len() as u64)
            .str(name)
            .str(media_type);
        self.with(|f| {
            f.send(Job::Outside {
                record,
                opcode: op::ATTACHMENT_INDEX,
                tail,
            })
        })
    }

    /// Close the chunk being filled and have what was written handed on. An error of
    /// the writer thread shows here once the thread has stopped on it (and at close).
    pub fn flush(&self) -> std::io::Result<()> {
        let stopped = lock(&self.writer)
            .as_ref()
            .is_some_and(JoinHandle::is_finished);
        self.with(|f| !stopped && f.send(Job::Flush))
    }

    /// Write the summary section and the footer: the file is complete, handed back.
    /// The first error of the recording, if any.
    pub fn close(&self) -> std::io::Result<W> {
        let logging = lock(&self.logging).take();
        let writer = lock(&self.writer).take();
        if let Some(e) = lock(&self.error).take() {
            return Err(e);
        }
        let (Some(mut logging), Some(writer)) = (logging, writer) else {
            return Err(closed());
        };
        let messages = std::mem::take(&mut logging.summary);
        // A failed send leaves the thread's own error to its result.
        let _ = logging.send(Job::Finish(messages));
        drop(logging);
        writer
            .join()
            .unwrap_or_else(|_| Err(std::io::Error::other("the MCAP writer thread panicked")))
    }
}

impl<W: Write + Send + 'static> std::fmt::Debug for McapFile<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile")
            .field("id", &self.id)
            .finish_non_exhaustive()
    }
}

fn closed() -> std::io::Error {
    std::io::Error::other("the MCAP file is closed")
}

impl<W: Write + Send + 'static> Sink for McapFile<W> {
    fn id(&self) -> SinkId {
        self.id
    }

    fn log(
        &self,
        channel: &RawChannel,
        msg: &[u8],
        metadata: &Metadata,
    ) -> Result<(), FoxgloveError> {
        self.with(|f| f.message(channel, msg, metadata.log_time))
            .map_err(FoxgloveError::IoError)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::{Context, PartialMetadata, Schema};
    use std::sync::Arc;

    /// A file of 50 messages on one channel and 17 on another (with a schema), chunks
    /// of 256 bytes, a metadata record and an attachment.
    fn written() -> Vec<u8> {
        let ctx = Context::new();
        let file = Arc::new(McapFile::create(Vec::new(), 256).unwrap());
        let meta = BTreeMap::from([("mode".to_owned(), "sil".to_owned())]);
        file.metadata("run", &meta).unwrap();
        file.attach("cfg.toml", "application/toml", 7, b"a = 1")
            .unwrap();
        ctx.add_sink(Arc::clone(&file) as Arc<dyn Sink>);
        let json = |topic: &str| ctx.channel_builder(topic).message_encoding("json");
        let a = json("/a").build_raw().unwrap();
        let schema = Schema::new("S", "jsonschema", br#"{"type":"object"}"#.to_vec());
        let b = json("/b").schema(schema).build_raw().unwrap();
        for k in 0..50u64 {
            let at = PartialMetadata::with_log_time(1_000 + k);
            a.log_with_meta(format!(r#"{{"k":{k}}}"#).as_bytes(), at);
            if k % 3 == 0 {
                b.log_with_meta(b"{}", PartialMetadata::with_log_time(2_000 - k));
            }
        }
        file.flush().unwrap();
        file.close().unwrap()
    }

    #[test]
    fn the_file_reads_back_whole_with_its_summary_indexes_and_crcs() {
        let bytes = written();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let stats = summary.stats.clone().unwrap();
        assert_eq!(stats.message_count, 67);
        assert_eq!((stats.channel_count, stats.schema_count), (2, 1));
        assert_eq!((stats.attachment_count, stats.metadata_count), (1, 1));
        assert_eq!(
            (stats.message_start_time, stats.message_end_time),
            (1_000, 2_000)
        );
        assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
        assert!(stats.chunk_count > 5, "{stats:?}");
        let indexed: usize = (summary.chunk_indexes.iter())
            .map(|c| summary.read_message_indexes(&bytes, c).unwrap())
            .map(|m| m.values().map(Vec::len).sum::<usize>())
            .sum();
        assert_eq!(indexed, 67);
        let checked = mcap::read::Options::ValidateChunkCrcs.into();
        let messages: Vec<_> = mcap::MessageStream::new_with_options(&bytes, checked)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let on_a: Vec<_> = messages
            .iter()
            .filter(|m| m.channel.topic == "/a")
            .collect();
        assert_eq!(on_a.len(), 50);
        assert_eq!(on_a[7].data.as_ref(), br#"{"k":7}"#);
        assert_eq!((on_a[7].sequence, on_a[7].log_time), (8, 1_007));
        let attachment = mcap::read::attachment(&bytes, &summary.attachment_indexes[0]).unwrap();
        assert_eq!(
            (attachment.name.as_str(), attachment.data.as_ref()),
            ("cfg.toml", &b"a = 1"[..])
        );
        let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
        assert_eq!(meta.metadata.get("mode").map(String::as_str), Some("sil"));
    }

    /// A disk that takes `room` bytes, then fails every write.
    struct Full {
        room: usize,
    }

    impl Write for Full {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if buf.len() > self.room {
                return Err(std::io::Error::other("disk full"));
            }
            self.room -= buf.len();
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_write_failing_on_the_writer_thread_shows_at_the_next_flush_and_at_close() {
        let ctx = Context::new();
        let file = Arc::new(McapFile::create(Full { room: 600 }, 256).unwrap());
        ctx.add_sink(Arc::clone(&file) as Arc<dyn Sink>);
        let a = ctx.channel_builder("/a").message_encoding("json");
        let a = a.build_raw().unwrap();
        for k in 0..20u64 {
            a.log_with_meta(b"{\"k\":0}", PartialMetadata::with_log_time(k));
        }
        // The writer thread fails on its own time: a flush reports it once it has.
        let failed = (0..10_000).find_map(|_| {
            std::thread::sleep(std::time::Duration::from_millis(1));
            file.flush().err()
        });
        assert!(
            failed
                .as_ref()
                .is_some_and(|e| e.to_string() == "disk full"),
            "{failed:?}"
        );
        let closed = file.close().map(|_| ());
        assert!(
            closed.as_ref().is_err_and(|e| e.to_string() == "disk full"),
            "{closed:?}"
        );
    }

    #[test]
    fn a_byte_changed_in_a_chunk_fails_its_crc() {
        let mut bytes = written();
        let at = (bytes.windows(7).position(|w| w == br#"{"k":7}"#)).unwrap();
        bytes[at + 5] = b'8';
        let checked = mcap::read::Options::ValidateChunkCrcs.into();
        let read: Result<Vec<_>, _> = mcap::MessageStream::new_with_options(&bytes, checked)
            .unwrap()
            .collect();
        assert!(
            matches!(read, Err(mcap::McapError::BadChunkCrc { .. })),
            "{read:?}"
        );
    }
}
