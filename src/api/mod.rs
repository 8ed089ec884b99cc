//! Protocol dialects: codecs between each protocol's JSON and the core's types.

pub mod rtk;
