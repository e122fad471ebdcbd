//! An MCAP file's records, framed and checked before anything in them is believed:
//! every record's length against the file and against its own fields, every chunk's
//! CRC, the data section's and the summary section's CRCs of a whole file, and the
//! message count its statistics give. A damaged record is a [`Damage`] naming its
//! byte offset; a file that ends inside a record (or after a whole record, without
//! its footer) is a recording cut by a kill ([`Cut`]), read up to its last whole
//! record.
//!
//! A cut and a damaged length can look alike (a length that points past the end of
//! the file), so a record that runs past the end is taken for a cut only where a kill
//! could have left it: in a file that does not end as a whole recording does (its end
//! magic), with a length no recording's record has ([`MAX_RECORD`]) refused, and a
//! chunk's length checked against its header when the cut left the header.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};

use mcap::records::{Record, op};

use crate::record::{CHUNK_SIZE, CONFIG_ATTACHMENT, RUN_METADATA};

/// The longest record a recording holds: a chunk closes once it reaches
/// [`CHUNK_SIZE`], so it holds that and one message more; other records are smaller.
const MAX_RECORD: u64 = 16 * CHUNK_SIZE;

/// A record's opcode and length.
const FRAME_HEADER: usize = 9;

/// A chunk header's fixed fields (times, sizes, CRC, the compression's length).
const CHUNK_HEADER_FIXED: usize = 8 + 8 + 8 + 4 + 4 + 8;

/// The length (and sizes) the writer puts in a chunk's header when it opens the chunk,
/// and overwrites when it closes it: a file cut by a kill ends in an open chunk.
const OPEN: u64 = u64::MAX;

/// What is wrong with a record, and where it starts (bytes from the file's start).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Damage {
    pub offset: u64,
    pub what: String,
}

impl Damage {
    fn at(offset: u64, what: impl Into<String>) -> Damage {
        Damage {
            offset,
            what: what.into(),
        }
    }
}

/// Why a file cannot be read as an MCAP file at all, or where it is damaged.
#[derive(Debug)]
pub enum ScanError {
    NotMcap(mcap::McapError),
    Damaged(Damage),
}

impl From<Damage> for ScanError {
    fn from(d: Damage) -> ScanError {
        ScanError::Damaged(d)
    }
}

/// Where a file cut by a kill ends: the offset of the first byte not read (the start
/// of the partial record, or the file's end), and why reading stopped there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cut {
    pub offset: u64,
    pub why: String,
}

/// A message record as read.
#[derive(Debug)]
pub struct RawMessage<'a> {
    /// Where its record starts in the file.
    pub offset: u64,
    pub channel: u16,
    pub log_time: u64,
    pub data: Cow<'a, [u8]>,
    /// The first and last log time its chunk's header gives.
    pub chunk_times: Option<(u64, u64)>,
}

/// What a file holds, in file order.
#[derive(Debug, Default)]
pub struct Scanned<'a> {
    pub channels: HashMap<u16, mcap::records::Channel>,
    /// The [`RUN_METADATA`] record's fields.
    pub run_metadata: Option<BTreeMap<String, String>>,
    /// The [`CONFIG_ATTACHMENT`]'s bytes.
    pub config: Option<Vec<u8>>,
    pub messages: Vec<RawMessage<'a>>,
    /// The last log time the summary's statistics give (a whole file).
    pub end_time: Option<u64>,
    /// The messages the summary's statistics count (a whole file).
    pub counted: Option<u64>,
    /// Where a cut file ends (`None`: the file is whole).
    pub cut: Option<Cut>,
    /// Where each chunk record starts, in file order.
    pub chunks: Vec<u64>,
    /// The file's length.
    pub len: u64,
}

/// One record's frame in a run of records.
enum Frame<'a> {
    Whole {
        offset: u64,
        opcode: u8,
        body: &'a [u8],
    },
    /// The record runs past the end of the bytes: its opcode, its length when the
    /// bytes hold it, and its bytes there are.
    Past {
        offset: u64,
        opcode: u8,
        len: Option<u64>,
        have: &'a [u8],
    },
}

/// The records of `bytes` one after the other, `base` the offset of `bytes` in the
/// file.
struct Frames<'a> {
    bytes: &'a [u8],
    at: usize,
    base: u64,
}

impl<'a> Frames<'a> {
    fn new(bytes: &'a [u8], base: u64) -> Frames<'a> {
        Frames { bytes, at: 0, base }
    }

    /// The offset in the file of the next record.
    fn offset(&self) -> u64 {
        self.base + self.at as u64
    }
}

impl<'a> Iterator for Frames<'a> {
    type Item = Result<Frame<'a>, Damage>;

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self.bytes.get(self.at..).filter(|r| !r.is_empty())?;
        let offset = self.offset();
        let opcode = rest[0];
        if !(op::HEADER..=op::DATA_END).contains(&opcode) {
            self.at = self.bytes.len();
            return Some(Err(Damage::at(
                offset,
                format!("{opcode:#04x} is no MCAP record's opcode"),
            )));
        }
        let len = rest
            .get(1..FRAME_HEADER)
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes);
        if let Some(len) = len.filter(|l| *l > MAX_RECORD && !(opcode == op::CHUNK && *l == OPEN)) {
            self.at = self.bytes.len();
            return Some(Err(Damage::at(
                offset,
                format!("a record of {len} bytes: no recording writes one over {MAX_RECORD}"),
            )));
        }
        let end = len.and_then(|l| FRAME_HEADER.checked_add(usize::try_from(l).ok()?));
        let Some(body) = end.and_then(|end| rest.get(FRAME_HEADER..end)) else {
            self.at = self.bytes.len();
            return Some(Ok(Frame::Past {
                offset,
                opcode,
                len,
                have: rest,
            }));
        };
        self.at += FRAME_HEADER + body.len();
        Some(Ok(Frame::Whole {
            offset,
            opcode,
            body,
        }))
    }
}

fn parse(offset: u64, opcode: u8, body: &[u8]) -> Result<Record<'_>, Damage> {
    mcap::parse_record(opcode, body).map_err(|e| Damage::at(offset, format!("record {e}")))
}

fn le_u64(bytes: &[u8], at: usize) -> Option<u64> {
    bytes
        .get(at..at + 8)
        .and_then(|b| b.try_into().ok())
        .map(u64::from_le_bytes)
}

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    bytes
        .get(at..at + 4)
        .and_then(|b| b.try_into().ok())
        .map(u32::from_le_bytes)
}

/// Read `bytes`, an MCAP file: whole, or cut by a kill.
pub fn scan(bytes: &[u8]) -> Result<Scanned<'_>, ScanError> {
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(ScanError::NotMcap(mcap::McapError::BadMagic));
    }
    // A whole recording ends with the magic; a cut one ends wherever the kill left it.
    let whole = bytes.len() >= 2 * mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
    let mut s = Scanned {
        len: bytes.len() as u64,
        ..Scanned::default()
    };
    let mut frames = Frames::new(&bytes[mcap::MAGIC.len()..], mcap::MAGIC.len() as u64);
    let mut summary_from = None;
    for frame in frames.by_ref() {
        let (offset, opcode, body) = match frame? {
            Frame::Whole {
                offset,
                opcode,
                body,
            } => (offset, opcode, body),
            Frame::Past {
                offset,
                opcode,
                len,
                have,
            } => {
                s.cut = Some(cut_inside(whole, s.len, offset, opcode, len, have)?);
                return Ok(s);
            }
        };
        if offset == mcap::MAGIC.len() as u64 && opcode != op::HEADER {
            return Err(Damage::at(offset, "the file does not start with a header record").into());
        }
        let end = offset + (FRAME_HEADER + body.len()) as u64;
        match opcode {
            op::DATA_END => {
                let data = 0..offset as usize;
                check_crc(offset, body, 4, bytes, data, "the data section")?;
                summary_from = Some(end as usize);
            }
            op::FOOTER => {
                // The summary's CRC runs to the footer's own CRC.
                let from = summary_from.ok_or_else(|| {
                    Damage::at(offset, "a footer record with no data end record before it")
                })?;
                let summary = from..end as usize - 4;
                check_crc(offset, body, 20, bytes, summary, "the summary section")?;
                return finish(s, end, &bytes[end as usize..], offset);
            }
            op::CHUNK => read_chunk(&mut s, offset, body)?,
            op::MESSAGE_INDEX => check_index(offset, body)?,
            _ => s.take(offset, parse(offset, opcode, body)?, None),
        }
    }
    let offset = frames.offset();
    if whole {
        return Err(Damage::at(offset, "the file ends without its footer record").into());
    }
    s.cut = Some(Cut {
        offset,
        why: "the file ends after a whole record, without its summary and footer".to_owned(),
    });
    Ok(s)
}

/// A file whose last record runs past its end: a cut, or damage where a kill could
/// not have left it.
fn cut_inside(
    whole: bool,
    file_len: u64,
    offset: u64,
    opcode: u8,
    len: Option<u64>,
    have: &[u8],
) -> Result<Cut, Damage> {
    let declared = len.map_or("its length cut off".to_owned(), |l| format!("{l} bytes"));
    if whole {
        return Err(Damage::at(
            offset,
            format!(
                "a record ({declared}) runs past the end of the file ({file_len} bytes), which ends as a whole recording does"
            ),
        ));
    }
    // A chunk cut after its header: an open one (the writer's placeholder length) has
    // the placeholder sizes, a closed one's sizes add up to its length.
    let body = have.get(FRAME_HEADER..).unwrap_or_default();
    let header = le_u32(body, 28).and_then(|clen| {
        let clen = usize::try_from(clen).ok()?;
        Some((clen, le_u64(body, CHUNK_HEADER_FIXED - 8 + clen)?))
    });
    if let (op::CHUNK, Some(len), Some((clen, compressed))) = (opcode, len, header) {
        let consistent = match len {
            OPEN => compressed == OPEN,
            _ => ((CHUNK_HEADER_FIXED + clen) as u64).checked_add(compressed) == Some(len),
        };
        if !consistent {
            return Err(Damage::at(
                offset,
                format!(
                    "a chunk's record is {declared} long, its header gives {compressed} bytes of data"
                ),
            ));
        }
    }
    let what = match (opcode, len) {
        (op::CHUNK, Some(OPEN)) => "its last chunk, still open (being written),".to_owned(),
        _ => format!("its last record (opcode {opcode:#04x}, {declared})"),
    };
    Ok(Cut {
        offset,
        why: format!("{what} is cut after {} bytes", have.len()),
    })
}

/// The CRC a data end or footer record at `offset` holds (`body`'s last 4 bytes, of
/// `len` bytes; 0: none written) against that of `bytes[range]`.
fn check_crc(
    offset: u64,
    body: &[u8],
    len: usize,
    bytes: &[u8],
    range: std::ops::Range<usize>,
    what: &str,
) -> Result<(), Damage> {
    let saved = le_u32(body, len - 4)
        .filter(|_| body.len() == len)
        .ok_or_else(|| {
            Damage::at(
                offset,
                format!(
                    "the record after {what} is {} bytes long, not {len}",
                    body.len()
                ),
            )
        })?;
    let calculated = crc32fast::hash(bytes.get(range.clone()).unwrap_or_default());
    if saved != 0 && saved != calculated {
        return Err(Damage::at(
            offset,
            format!(
                "{what} (bytes {} to {}) fails its CRC: {calculated:#010x}, the record says {saved:#010x}",
                range.start, range.end
            ),
        ));
    }
    Ok(())
}

/// The file after its footer: its end magic, and nothing more; the statistics' count
/// against the messages read.
fn finish<'a>(
    s: Scanned<'a>,
    end: u64,
    after: &[u8],
    footer: u64,
) -> Result<Scanned<'a>, ScanError> {
    if after != mcap::MAGIC {
        return Err(Damage::at(
            end,
            format!(
                "{} bytes after the footer record, not the end magic",
                after.len()
            ),
        )
        .into());
    }
    if let Some(counted) = s.counted
        && counted != s.messages.len() as u64
    {
        return Err(Damage::at(
            footer,
            format!(
                "the statistics count {counted} messages, the file holds {}",
                s.messages.len()
            ),
        )
        .into());
    }
    Ok(s)
}

/// A message index: its length is its entries' exactly (a longer one would hide the
/// records after it, a shorter one cut into them).
fn check_index(offset: u64, body: &[u8]) -> Result<(), Damage> {
    let Record::MessageIndex(index) = parse(offset, op::MESSAGE_INDEX, body)? else {
        return Err(Damage::at(offset, "not a message index record"));
    };
    let expected = 2 + 4 + 16 * index.records.len();
    if body.len() != expected {
        return Err(Damage::at(
            offset,
            format!(
                "a message index record is {} bytes long, its {} entries {expected}",
                body.len(),
                index.records.len()
            ),
        ));
    }
    Ok(())
}

/// A chunk: its length against its header, its CRC, then its records.
fn read_chunk<'a>(s: &mut Scanned<'a>, offset: u64, body: &'a [u8]) -> Result<(), Damage> {
    let Record::Chunk { header, data } = parse(offset, op::CHUNK, body)? else {
        return Err(Damage::at(offset, "not a chunk record"));
    };
    let Cow::Borrowed(data) = data else {
        return Err(Damage::at(offset, "a chunk's data not in the file"));
    };
    let header_len = CHUNK_HEADER_FIXED + header.compression.len();
    if (header_len + data.len()) as u64 != body.len() as u64 {
        return Err(Damage::at(
            offset,
            format!(
                "a chunk's record is {} bytes long, its header and data {}",
                body.len(),
                header_len + data.len()
            ),
        ));
    }
    if !header.compression.is_empty() || header.uncompressed_size != data.len() as u64 {
        return Err(Damage::at(
            offset,
            format!(
                "a chunk compressed with {:?} ({} bytes, {} uncompressed): recordings are written uncompressed",
                header.compression,
                data.len(),
                header.uncompressed_size
            ),
        ));
    }
    let calculated = crc32fast::hash(data);
    if header.uncompressed_crc != 0 && header.uncompressed_crc != calculated {
        return Err(Damage::at(
            offset,
            format!(
                "a chunk of {} bytes fails its CRC: {calculated:#010x}, its header says {:#010x}",
                data.len(),
                header.uncompressed_crc
            ),
        ));
    }
    s.chunks.push(offset);
    let times = (header.message_start_time, header.message_end_time);
    let base = offset + (FRAME_HEADER + header_len) as u64;
    for frame in Frames::new(data, base) {
        match frame? {
            Frame::Whole {
                offset: at,
                opcode,
                body,
            } => s.take(at, parse(at, opcode, body)?, Some(times)),
            Frame::Past { offset: at, .. } => {
                return Err(Damage::at(
                    at,
                    format!("a record runs past the end of its chunk (at byte {offset})"),
                ));
            }
        }
    }
    Ok(())
}

impl<'a> Scanned<'a> {
    /// A record outside a chunk or inside one (`chunk_times`).
    fn take(&mut self, offset: u64, record: Record<'a>, chunk_times: Option<(u64, u64)>) {
        match record {
            Record::Channel(c) => {
                self.channels.insert(c.id, c);
            }
            Record::Message { header, data } => self.messages.push(RawMessage {
                offset,
                channel: header.channel_id,
                log_time: header.log_time,
                data,
                chunk_times,
            }),
            Record::Metadata(m) if m.name == RUN_METADATA => self.run_metadata = Some(m.metadata),
            Record::Attachment { header, data, .. } if header.name == CONFIG_ATTACHMENT => {
                self.config = Some(data.into_owned());
            }
            Record::Statistics(st) => {
                self.end_time = Some(st.message_end_time);
                self.counted = Some(st.message_count);
            }
            _ => {}
        }
    }
}
