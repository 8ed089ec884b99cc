//! ROS bags read a message at a time: ROS1 bags (`#ROSBAG V2.0`, chunks plain, bz2 or lz4)
//! and ROS 2 bags stored as MCAP (CDR messages; a rosbag2 folder or its `.mcap` file).

pub mod messages;

use std::io::Read;
use std::path::{Path, PathBuf};

use super::InterchangeError;

/// What kind of bag a file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagKind {
    /// A ROS1 bag: messages in ROS1's serialisation.
    Ros1,
    /// A ROS 2 bag in MCAP: messages in CDR.
    Ros2,
}

/// A topic of a bag: its name and type (`sensor_msgs/NavSatFix`, or ROS 2's
/// `sensor_msgs/msg/NavSatFix`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    /// The name.
    pub name: String,
    /// The type as the bag writes it.
    pub msg_type: String,
}

impl Topic {
    /// The type without ROS 2's `/msg/`: `sensor_msgs/NavSatFix` either way.
    pub fn plain_type(&self) -> String {
        self.msg_type.replacen("/msg/", "/", 1)
    }
}

/// MCAP's file magic.
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
/// A ROS1 bag's first line.
const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// The largest read handed to the MCAP reader at once, bytes (its request is a hint taken
/// from the file, so a claim, not a size).
const MCAP_READ: usize = 1 << 20;
/// The largest record or chunk (decompressed) a bag may claim, bytes: rosbag writes chunks of
/// 768 KiB and rosbag2's MCAP writer of 4 MiB by default; a claim beyond this is refused
/// before anything is allocated for it.
const MAX_RECORD: usize = 256 << 20;
/// The largest compressed chunk of a ROS1 bag, bytes: its decompression is bounded by the
/// ratio lz4 and bz2 reach on it.
const MAX_COMPRESSED_CHUNK: u64 = 16 << 20;

/// The bag file at `path` (a ROS 2 bag's folder: the `.mcap` file in it) and its kind.
pub fn open(path: &Path) -> Result<(PathBuf, BagKind), InterchangeError> {
    let file = if path.is_dir() {
        let mut found: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(|e| InterchangeError::io(path, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect();
        found.sort();
        match found.len() {
            1 => found.remove(0),
            0 => {
                return Err(InterchangeError::Refused(format!(
                    "{}: a folder without an .mcap file (a rosbag2 folder in sqlite3 is \
                     not read: convert it with `ros2 bag convert` to MCAP)",
                    path.display()
                )));
            }
            _ => {
                return Err(InterchangeError::Refused(format!(
                    "{}: several .mcap files ({}); name the one to import",
                    path.display(),
                    found.len()
                )));
            }
        }
    } else {
        path.to_owned()
    };
    let mut head = [0u8; 13];
    let n = std::fs::File::open(&file)
        .and_then(|mut f| f.read(&mut head))
        .map_err(|e| InterchangeError::io(&file, e))?;
    let head = &head[..n];
    let kind = if head.starts_with(MCAP_MAGIC) {
        BagKind::Ros2
    } else if head.starts_with(ROS1_MAGIC) {
        BagKind::Ros1
    } else {
        return Err(InterchangeError::Refused(format!(
            "{}: neither a ROS1 bag (#ROSBAG V2.0) nor an MCAP file",
            file.display()
        )));
    };
    Ok((file, kind))
}

/// Hands every message of the bag `file` of `kind` to `each`: its topic, the time it was
/// logged (ns since 1970) and its serialised bytes, in the order the bag holds them.
pub fn read(
    file: &Path,
    kind: BagKind,
    each: &mut dyn FnMut(&Topic, u64, &[u8]),
) -> Result<(), InterchangeError> {
    match kind {
        BagKind::Ros1 => read_ros1(file, each),
        BagKind::Ros2 => read_mcap(file, each),
    }
}

fn read_ros1(
    file: &Path,
    each: &mut dyn FnMut(&Topic, u64, &[u8]),
) -> Result<(), InterchangeError> {
    use rosbag::{ChunkRecord, IndexRecord, MessageRecord};
    let refused = |e: rosbag::Error| {
        InterchangeError::Refused(format!("{}: not a readable ROS1 bag: {e}", file.display()))
    };
    check_ros1_chunks(file)?;
    let bag = rosbag::RosBag::new(file).map_err(|e| InterchangeError::io(file, e))?;
    let mut topics: std::collections::HashMap<u32, Topic> = std::collections::HashMap::new();
    for record in bag.index_records() {
        if let IndexRecord::Connection(c) = record.map_err(refused)? {
            topics.insert(
                c.id,
                Topic {
                    name: c.topic.to_owned(),
                    msg_type: c.tp.to_owned(),
                },
            );
        }
    }
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) = record.map_err(refused)? else {
            continue;
        };
        for message in chunk.messages() {
            match message.map_err(refused)? {
                MessageRecord::MessageData(m) => {
                    if let Some(topic) = topics.get(&m.conn_id) {
                        each(topic, m.time, m.data);
                    }
                }
                MessageRecord::Connection(c) => {
                    topics.entry(c.id).or_insert_with(|| Topic {
                        name: c.topic.to_owned(),
                        msg_type: c.tp.to_owned(),
                    });
                }
            }
        }
    }
    Ok(())
}

fn read_mcap(
    file: &Path,
    each: &mut dyn FnMut(&Topic, u64, &[u8]),
) -> Result<(), InterchangeError> {
    use mcap::records::Record;
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let mut f = std::fs::File::open(file).map_err(|e| InterchangeError::io(file, e))?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(MAX_RECORD),
    );
    let mut schemas: std::collections::HashMap<u16, String> = std::collections::HashMap::new();
    let mut topics: std::collections::HashMap<u16, Topic> = std::collections::HashMap::new();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| InterchangeError::mcap(file, e))? {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n.clamp(1, MCAP_READ));
                let read = f.read(buf).map_err(|e| InterchangeError::io(file, e))?;
                reader.notify_read(read);
            }
            LinearReadEvent::Record { data, opcode } => {
                match mcap::parse_record(opcode, data)
                    .map_err(|e| InterchangeError::mcap(file, e))?
                {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name.clone());
                    }
                    Record::Channel(c) => {
                        let msg_type = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        // ROS 2's messages are CDR; a channel of another encoding is not a
                        // ROS 2 topic and is passed over.
                        if c.message_encoding == "cdr" {
                            topics.insert(
                                c.id,
                                Topic {
                                    name: c.topic.clone(),
                                    msg_type,
                                },
                            );
                        }
                    }
                    Record::Message { header, data } => {
                        if let Some(topic) = topics.get(&header.channel_id) {
                            each(topic, header.log_time, &data);
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

/// Walks a ROS1 bag's records (each a header of `name=value` fields and data, both
/// length-prefixed) and refuses a chunk whose claimed size, or whose compressed data, is
/// beyond what is read: the rosbag crate allocates what a chunk claims before it looks.
fn check_ros1_chunks(file: &Path) -> Result<(), InterchangeError> {
    use std::io::{BufReader, Seek, SeekFrom};
    let refused = |why: String| {
        InterchangeError::Refused(format!(
            "{}: not a readable ROS1 bag: {why}",
            file.display()
        ))
    };
    let f = std::fs::File::open(file).map_err(|e| InterchangeError::io(file, e))?;
    let total = f
        .metadata()
        .map_err(|e| InterchangeError::io(file, e))?
        .len();
    let mut r = BufReader::new(f);
    r.seek(SeekFrom::Start(ROS1_MAGIC.len() as u64))
        .map_err(|e| InterchangeError::io(file, e))?;
    let mut at = ROS1_MAGIC.len() as u64;
    let u32_at = |r: &mut BufReader<std::fs::File>| -> Result<u32, InterchangeError> {
        let mut b = [0u8; 4];
        r.read_exact(&mut b)
            .map_err(|e| InterchangeError::io(file, e))?;
        Ok(u32::from_le_bytes(b))
    };
    while at < total {
        let header_len = u64::from(u32_at(&mut r)?);
        if header_len > 1 << 20 || at + 4 + header_len + 4 > total {
            return Err(refused(format!(
                "a record header of {header_len} bytes at byte {at}"
            )));
        }
        let mut header = vec![0u8; header_len as usize];
        r.read_exact(&mut header)
            .map_err(|e| InterchangeError::io(file, e))?;
        let data_len = u64::from(u32_at(&mut r)?);
        let end = at + 4 + header_len + 4 + data_len;
        if end > total {
            return Err(refused(format!(
                "a record at byte {at} runs past the file's end"
            )));
        }
        let (op, size, compression) = header_fields(&header);
        if op == Some(0x05) {
            let size =
                size.ok_or_else(|| refused(format!("a chunk at byte {at} states no size")))?;
            let compressed = compression.is_some_and(|c| c != b"none");
            if size as usize > MAX_RECORD
                || (compressed && data_len > MAX_COMPRESSED_CHUNK)
                || (!compressed && u64::from(size) != data_len)
            {
                return Err(refused(format!(
                    "a chunk at byte {at} claims {size} bytes from {data_len} (at most {MAX_RECORD} \
                     are read, from at most {MAX_COMPRESSED_CHUNK} compressed)"
                )));
            }
        }
        r.seek(SeekFrom::Start(end))
            .map_err(|e| InterchangeError::io(file, e))?;
        at = end;
    }
    Ok(())
}

/// A ROS1 record header's `op`, `size` and `compression` fields.
fn header_fields(mut header: &[u8]) -> (Option<u8>, Option<u32>, Option<&[u8]>) {
    let (mut op, mut size, mut compression) = (None, None, None);
    while let Some((len, rest)) = header.split_first_chunk::<4>() {
        let len = u32::from_le_bytes(*len) as usize;
        let Some((field, rest)) = rest.split_at_checked(len) else {
            break;
        };
        header = rest;
        let Some(eq) = field.iter().position(|b| *b == b'=') else {
            continue;
        };
        let (name, value) = (&field[..eq], &field[eq + 1..]);
        match name {
            b"op" => op = value.first().copied(),
            b"size" => size = value.first_chunk::<4>().map(|v| u32::from_le_bytes(*v)),
            b"compression" => compression = Some(value),
            _ => {}
        }
    }
    (op, size, compression)
}
