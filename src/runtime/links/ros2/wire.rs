//! How the node's process puts the CDR of [`super::messages`] on ros2-client's writers and
//! takes it from its readers, without a Rust type per topic: the writers carry payloads
//! already serialised, the readers hand over the payload as it came.

use serde::de::{DeserializeSeed, SeqAccess, Visitor};
use serde::ser::SerializeTuple;

/// A CDR payload already serialised. ros2-client serialises a writer's sample with its CDR
/// serializer; a tuple of bytes is written as the bytes themselves (CDR gives a tuple no
/// length and a byte no alignment), so the payload goes out unchanged.
#[derive(Debug, Clone, PartialEq)]
pub struct RawCdr(pub Vec<u8>);

impl serde::Serialize for RawCdr {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut tuple = serializer.serialize_tuple(self.0.len())?;
        for byte in &self.0 {
            tuple.serialize_element(byte)?;
        }
        tuple.end()
    }
}

/// Takes a sample's CDR payload as it came, for the node to decode strictly by its type
/// ([`super::messages::decode`]): ros2-client hands a reader's seed a CDR deserializer
/// positioned at the payload, which gives it byte after byte until the payload ends.
#[derive(Debug, Clone, Copy)]
pub struct RawSeed;

impl<'de> DeserializeSeed<'de> for RawSeed {
    type Value = Vec<u8>;

    fn deserialize<D: serde::Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_tuple(usize::MAX, RawBytes)
    }
}

/// [`RawSeed`]'s visitor: every byte up to the end of the payload.
struct RawBytes;

impl<'de> Visitor<'de> for RawBytes {
    type Value = Vec<u8>;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a CDR payload")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut bytes: A) -> Result<Vec<u8>, A::Error> {
        let mut payload = Vec::new();
        // The payload's end is the deserializer's error: what came before is the payload.
        while let Ok(Some(byte)) = bytes.next_element::<u8>() {
            payload.push(byte);
        }
        Ok(payload)
    }
}

#[cfg(test)]
mod tests {
    use byteorder::LittleEndian;
    use serde_json::json;

    use super::*;
    use crate::runtime::links::ros2::messages::{cdr, decode};

    #[test]
    fn a_payload_goes_out_as_it_was_serialised() {
        let twist = json!({"linear": {"x": 0.5, "y": 0.0, "z": 0.0},
                           "angular": {"x": 0.0, "y": 0.0, "z": -0.25}});
        let payload = cdr("geometry_msgs/msg/Twist", &twist).unwrap();
        let through = cdr_encoding::to_vec::<_, LittleEndian>(&RawCdr(payload.clone())).unwrap();
        assert_eq!(through, payload);
        // A string (a length, then bytes) and then a double: alignment as at the start.
        let stamped = json!({"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "abc"},
                             "twist": twist});
        let payload = cdr("geometry_msgs/msg/TwistStamped", &stamped).unwrap();
        let through = cdr_encoding::to_vec::<_, LittleEndian>(&RawCdr(payload.clone())).unwrap();
        assert_eq!(through, payload);
    }

    #[test]
    fn the_seed_takes_the_payload_whole_and_nothing_more() {
        let pose = json!({"header": {"stamp": {"sec": 3, "nanosec": 4}, "frame_id": "map"},
                          "pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0},
                                   "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}});
        let payload = cdr("geometry_msgs/msg/PoseStamped", &pose).unwrap();
        let mut deserializer = cdr_encoding::CdrDeserializer::<LittleEndian>::new(&payload);
        let taken = RawSeed.deserialize(&mut deserializer).unwrap();
        assert_eq!(taken, payload);
        assert_eq!(
            decode("geometry_msgs/msg/PoseStamped", &taken).unwrap(),
            pose
        );
        let mut empty = cdr_encoding::CdrDeserializer::<LittleEndian>::new(&[]);
        assert_eq!(RawSeed.deserialize(&mut empty).unwrap(), Vec::<u8>::new());
    }
}
