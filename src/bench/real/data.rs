//! The shared data's robot recordings: CSV files with a header row, one row per sample.

use std::collections::HashMap;
use std::path::Path;

use crate::bench::error::{invalid, missing};

/// Reads one CSV with a header row: the named columns of every row (the shared data's robot
/// recordings).
pub fn columns(path: &Path, names: &[&str]) -> crate::bench::error::Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path)
        .map_err(invalid(format!("cannot read {}", path.display())))?;
    let mut lines = text.lines();
    let header: HashMap<&str, usize> = lines
        .next()
        .ok_or_else(missing("empty file"))?
        .split(',')
        .enumerate()
        .map(|(i, h)| (h, i))
        .collect();
    let index: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .get(n)
                .copied()
                .ok_or_else(missing(format!("{}: no column {n}", path.display())))
        })
        .collect::<crate::bench::error::Result<_>>()?;
    lines
        .filter(|l| !l.is_empty())
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            index
                .iter()
                .map(|&i| {
                    cells
                        .get(i)
                        .and_then(|c| c.parse::<f64>().ok())
                        .ok_or_else(missing(format!("{}: bad row {l}", path.display())))
                })
                .collect()
        })
        .collect()
}

/// The last sample at or before `t` (samples sorted by their first column; the first when
/// `t` is earlier).
pub fn sample_at(samples: &[Vec<f64>], t: f64) -> &[f64] {
    let i = samples.partition_point(|s| s[0] <= t);
    &samples[i.saturating_sub(1)]
}

/// A skid-steered robot's wheel odometry yaw rate over its gyro's: least squares over the
/// samples turning faster than 0.2 rad/s (`odom` rows t, vx, wz; `gyro` rows t, yaw rate).
/// Skid steering slips in turns, so the wheels' yaw rate is a multiple of the truth's.
pub fn wheel_to_gyro_ratio(odom: &[Vec<f64>], gyro: &[Vec<f64>]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for o in odom {
        let g = sample_at(gyro, o[0])[1];
        if g.abs() > 0.2 {
            num += o[2] * g;
            den += g * g;
        }
    }
    if den > 0.0 { num / den } else { 1.0 }
}
