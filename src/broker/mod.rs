//! The embedded broker's gate, sans-IO: MQTT packets framed and CONNECT read ([`wire`]),
//! and who is let in ([`admission`]). The sockets, the broker process and its supervision
//! are `runtime::broker`'s.

pub mod admission;
pub mod wire;
