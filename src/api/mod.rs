//! Protocol dialects: codecs between each protocol's JSON and the core's types.

pub mod local;
pub mod mqtt;
pub mod rtk;
