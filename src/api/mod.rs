//! Protocol dialects: codecs between each protocol's JSON and the core's types.

pub mod device;
pub mod local;
pub mod mqtt;
pub mod root;
pub mod rtk;
