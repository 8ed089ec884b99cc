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
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};
    let mut f = std::fs::File::open(file).map_err(|e| InterchangeError::io(file, e))?;
    let mut reader = LinearReader::new();
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
