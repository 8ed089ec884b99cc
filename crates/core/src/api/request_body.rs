//! The body of every MQTT dialect's request: no larger than the link's limit and one JSON
//! object, checked once before any command reads a field. Each dialect answers a failure with
//! its own code, chosen by matching on [`BodyError`].

use serde_json::{Map, Value};

/// A request's fields.
pub type Fields = Map<String, Value>;

/// Why a payload is not a request.
#[derive(Debug, thiserror::Error)]
pub enum BodyError {
    /// Larger than the link takes.
    #[error("payload of {len} bytes exceeds {max}")]
    TooLarge {
        /// Its size, bytes.
        len: usize,
        /// The limit, bytes.
        max: usize,
    },
    /// Not JSON.
    #[error("malformed JSON: {0}")]
    Malformed(serde_json::Error),
    /// JSON, but not an object.
    #[error("the request must be a JSON object")]
    NotAnObject,
}

/// The fields of `payload`, which may hold at most `max` bytes.
pub fn fields(payload: &[u8], max: usize) -> Result<Fields, BodyError> {
    if payload.len() > max {
        return Err(BodyError::TooLarge {
            len: payload.len(),
            max,
        });
    }
    match serde_json::from_slice(payload).map_err(BodyError::Malformed)? {
        Value::Object(fields) => Ok(fields),
        _ => Err(BodyError::NotAnObject),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_body_is_checked_for_size_then_syntax_then_shape() {
        assert!(matches!(
            fields(b"{}", 1),
            Err(BodyError::TooLarge { len: 2, max: 1 })
        ));
        let malformed = fields(b"{", 10).unwrap_err();
        assert!(malformed.to_string().starts_with("malformed JSON: "));
        assert!(matches!(fields(b"[1]", 10), Err(BodyError::NotAnObject)));
        assert_eq!(fields(br#"{"a":1}"#, 10).unwrap()["a"], 1);
    }
}
