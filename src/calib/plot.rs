//! The report plot of a calibration (SVG): for `imu` the gyro's z rate over the run with the
//! still span and the bias found; for `odometry` and `gnss` the antenna's measured path
//! against the fitted one, and each fix's miss.

use std::path::Path;

use std::path::PathBuf;

use plotters::prelude::*;

use super::data::Dataset;
use super::{Found, Procedure};

/// Drawn points per series at most (a long run is thinned evenly).
const MAX_POINTS: usize = 4000;

fn thin<T: Copy>(v: &[T]) -> impl Iterator<Item = T> + '_ {
    let step = v.len().div_ceil(MAX_POINTS).max(1);
    v.iter().step_by(step).copied()
}

/// Draws the report of `procedure` into the SVG file `path`.
pub fn draw(
    procedure: Procedure,
    data: &Dataset,
    found: &Found,
    path: &Path,
) -> Result<(), PlotError> {
    let root = SVGBackend::new(path, (1200, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    match procedure {
        Procedure::Imu => draw_imu(&root, data, found)?,
        Procedure::Odometry | Procedure::Gnss => draw_motion(&root, procedure, found)?,
    }
    root.present().map_err(|e| PlotError::Write {
        path: path.to_owned(),
        error: e.to_string(),
    })?;
    Ok(())
}

/// Why the plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Drawing failed (plotters' own words).
    #[error("{0}")]
    Draw(String),
    /// The file could not be written.
    #[error("cannot write the plot {}: {error}", .path.display())]
    Write {
        /// The SVG file.
        path: PathBuf,
        /// Why.
        error: String,
    },
}

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PlotError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        Self::Draw(e.to_string())
    }
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo.is_finite() && hi > lo {
        let pad = (hi - lo) * 0.05;
        (lo - pad, hi + pad)
    } else {
        (-1.0, 1.0)
    }
}

fn draw_imu(root: &Area, data: &Dataset, found: &Found) -> Result<(), PlotError> {
    let Some(r) = &found.imu else {
        return Ok(());
    };
    // The still span and 10 s either side: the driving around it would bury it.
    let (t0, t1) = (r.span.0 - 10.0, r.span.1 + 10.0);
    let near: Vec<_> = data
        .imu
        .iter()
        .filter(|p| p.t >= t0 && p.t <= t1)
        .copied()
        .collect();
    let points: Vec<(f64, f64)> = thin(&near).map(|p| (p.t, p.gyro.z.to_degrees())).collect();
    // The still span's rates set the scale: driving would flatten them to a line.
    let still: Vec<f64> = points
        .iter()
        .filter(|p| p.0 >= r.span.0 && p.0 <= r.span.1)
        .map(|p| p.1)
        .collect();
    let (lo, hi) = range(still.iter().copied());
    let bias = r.gyro_bias_rps[2].to_degrees();
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "imu: gyro z at rest, bias {bias:.4} °/s over {:.1} s (shaded)",
                r.span.1 - r.span.0
            ),
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t0..t1, lo..hi)?;
    chart
        .configure_mesh()
        .x_desc("time in the recording, s")
        .y_desc("gyro z, °/s")
        .draw()?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(r.span.0, lo), (r.span.1, hi)],
        RGBColor(220, 235, 250).filled(),
    )))?;
    chart.draw_series(LineSeries::new(
        points.iter().map(|&(t, v)| (t, v.clamp(lo, hi))),
        BLUE.stroke_width(1),
    ))?;
    chart
        .draw_series(LineSeries::new(
            [(t0, bias), (t1, bias)],
            RED.stroke_width(2),
        ))?
        .label("bias")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
    chart.configure_series_labels().border_style(BLACK).draw()?;
    Ok(())
}

fn draw_motion(root: &Area, procedure: Procedure, found: &Found) -> Result<(), PlotError> {
    let Some(m) = &found.motion else {
        return Ok(());
    };
    let (left, right) = root.split_horizontally(620);
    let all = m.fitted.iter().flat_map(|w| w.measured.iter());
    let (e0, e1) = range(all.clone().map(|p| p[0]));
    let (n0, n1) = range(all.map(|p| p[1]));
    // Equal scales on both axes: a circle stays a circle.
    let half = ((e1 - e0).max(n1 - n0)) / 2.0;
    let (ec, nc) = ((e0 + e1) / 2.0, (n0 + n1) / 2.0);
    let title = match procedure {
        Procedure::Odometry => format!(
            "odometry: radii {:.5} / {:.5} m, track {:.4} m",
            m.radius.left, m.radius.right, m.track_m
        ),
        _ => format!(
            "gnss: antenna ({:.3}, {:.3}) m, heading offset {}",
            m.antenna[0],
            m.antenna[1],
            m.heading_offset_deg
                .map_or("not measured".into(), |h| format!("{h:.2}°"))
        ),
    };
    let mut chart = ChartBuilder::on(&left)
        .caption(title, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(ec - half..ec + half, nc - half..nc + half)?;
    chart
        .configure_mesh()
        .x_desc("east, m")
        .y_desc("north, m")
        .draw()?;
    let fixes: usize = m.fitted.iter().map(|w| w.measured.len()).sum();
    let step = fixes.div_ceil(MAX_POINTS / 2).max(1);
    for w in &m.fitted {
        chart.draw_series(
            w.measured
                .iter()
                .step_by(step)
                .map(|p| Circle::new((p[0], p[1]), 1, BLUE.filled())),
        )?;
        chart.draw_series(LineSeries::new(
            w.model.iter().map(|p| (p[0], p[1])),
            RED.stroke_width(1),
        ))?;
    }
    let misses: Vec<(f64, f64)> = m
        .fitted
        .iter()
        .flat_map(|w| w.measured.iter().zip(&w.model))
        .enumerate()
        .map(|(i, (a, b))| (i as f64, (a[0] - b[0]).hypot(a[1] - b[1]) * 1000.0))
        .collect();
    let (_, top) = range(misses.iter().map(|p| p.1));
    let mut chart = ChartBuilder::on(&right)
        .caption(
            format!(
                "each fix's miss: RMS {:.1} mm per axis, {} windows",
                m.residual_m * 1000.0,
                m.windows
            ),
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..misses.len().max(1) as f64, 0.0..top.max(1.0))?;
    chart
        .configure_mesh()
        .x_desc("fix (windows in time order)")
        .y_desc("measured − fitted, mm")
        .draw()?;
    chart.draw_series(
        misses
            .iter()
            .step_by(step)
            .map(|&p| Circle::new(p, 1, BLACK.filled())),
    )?;
    Ok(())
}
