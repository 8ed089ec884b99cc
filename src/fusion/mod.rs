//! Localisation: geodesy and the fusion filter.

pub mod geodesy;
