//! The embedded broker's gate, sans-IO: MQTT packets framed and CONNECT read ([`wire`]),
//! who is let in ([`admission`]), and what each session may send ([`session`]). The sockets, the broker process and its supervision
//! are `runtime::links::broker`'s.

pub mod admission;
mod cursor;
pub mod held;
pub mod session;
pub mod wire;
