//! A path prepared for following: cleaned of points too close together, split where it
//! turns sharply (the vehicle stops and turns on the spot there), sampled at equal spacing,
//! with the heading, curvature and speed limit at each sample.
//!
//! - Points closer than [`MIN_SPACING_M`] to the last one kept are dropped: a recording at
//!   10 Hz standing still, or a GNSS jitter of a centimetre, must not read as a sharp turn.
//! - A vertex turning by more than [`CORNER_RAD`] ends a segment.
//! - Heading and curvature come from windows of [`HEADING_WINDOW_M`] and
//!   [`CURVATURE_WINDOW_M`], so a polyline of chords through a curve reads as the curve.
//! - The speed limit keeps the sideways acceleration and the yaw rate within the limits,
//!   and brakes on the deceleration limit for the end of each segment.

use crate::control::moves::planning_limits;
use crate::control::settings::MotionSettings;
use crate::fusion::planar::wrap;

/// The longest path, m: 400,000 samples (some 19 MB) at most. A longer coverage is split
/// into several steps.
pub const MAX_LENGTH_M: f64 = 20_000.0;
/// Points closer than this to the last one kept are dropped, m.
pub const MIN_SPACING_M: f64 = 0.1;
/// A vertex turning more than this is a corner, rad (45°).
pub const CORNER_RAD: f64 = std::f64::consts::FRAC_PI_4;
/// Sample spacing, m.
pub const SAMPLE_M: f64 = 0.05;
/// Heading is the direction across this much path, m.
const HEADING_WINDOW_M: f64 = 0.2;
/// Curvature is the heading change across this much path, m.
const CURVATURE_WINDOW_M: f64 = 0.4;
/// The share of the yaw-rate limit the curvature may take at speed: the rest corrects.
const YAW_RATE_SHARE: f64 = 0.7;

/// One sample of a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Distance from the segment's start, m.
    pub s: f64,
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Direction of travel, rad.
    pub yaw: f64,
    /// Curvature, 1/m (positive left).
    pub kappa: f64,
    /// The most speed here, m/s.
    pub v_max: f64,
}

/// A stretch driven without stopping.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Samples from start to end (at least two).
    pub samples: Vec<Sample>,
}

impl Segment {
    /// Its length, m.
    pub fn length(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.s)
    }

    /// The speed limit at distance `s` along it, braking for its end too, m/s.
    pub fn speed_limit(&self, s: f64, decel: f64) -> f64 {
        let f = (s / SAMPLE_M).clamp(0.0, (self.samples.len() - 1) as f64);
        let (i, frac) = (f.floor() as usize, f.fract());
        let a = self.samples[i].v_max;
        let b = self.samples.get(i + 1).map_or(a, |n| n.v_max);
        let end = (2.0 * decel * (self.length() - s).max(0.0)).sqrt();
        (a + (b - a) * frac).min(end)
    }

    /// The sample nearest to distance `s` along it.
    pub fn at(&self, s: f64) -> &Sample {
        let i = (s / SAMPLE_M)
            .round()
            .clamp(0.0, (self.samples.len() - 1) as f64) as usize;
        &self.samples[i]
    }
}

/// A path ready to follow.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Segments in driving order; none when the path has no length.
    pub segments: Vec<Segment>,
}

impl Track {
    /// The track through `points` (map frame, m) at up to `speed` (m/s) under `settings`;
    /// the caller keeps their length within [`MAX_LENGTH_M`] (memory grows with it).
    pub fn new(points: &[(f64, f64)], speed: f64, settings: &MotionSettings) -> Self {
        let kept = thin(points);
        let segments = split_at_corners(&kept)
            .into_iter()
            .map(|corners| sample(&corners, speed, settings))
            .collect();
        Self { segments }
    }

    /// Total length, m.
    pub fn length(&self) -> f64 {
        self.segments.iter().map(Segment::length).sum()
    }

    /// The time to drive it at its speed limits, accelerating at the limit, plus the turns
    /// at its corners, s.
    pub fn planned_s(&self, settings: &MotionSettings) -> f64 {
        let limits = planning_limits(settings.linear);
        let mut total = 0.0;
        for segment in &self.segments {
            let mut v: f64 = 0.0;
            for pair in segment.samples.windows(2) {
                let ds = pair[1].s - pair[0].s;
                let next = segment
                    .speed_limit(pair[1].s, limits.decel)
                    .min((v * v + 2.0 * limits.accel * ds).sqrt());
                total += 2.0 * ds / (v + next).max(1e-3);
                v = next;
            }
        }
        for pair in self.segments.windows(2) {
            let (end, start) = (pair[0].samples.last(), pair[1].samples.first());
            if let (Some(end), Some(start)) = (end, start) {
                let turn = wrap(start.yaw - end.yaw);
                total += super::profile::Profile::plan(turn, settings.angular).duration();
            }
        }
        total
    }
}

/// Drops points closer than [`MIN_SPACING_M`] to the last kept; the last point stays (it
/// replaces a kept one too close to it), so the path ends where it was asked to.
fn thin(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut kept: Vec<(f64, f64)> = Vec::with_capacity(points.len());
    for &p in points {
        match kept.last() {
            Some(&last) if distance(last, p) < MIN_SPACING_M => {}
            _ => kept.push(p),
        }
    }
    if let (Some(&last), Some(kept_last)) = (points.last(), kept.last_mut())
        && *kept_last != last
    {
        if kept.len() >= 2 {
            let n = kept.len();
            kept[n - 1] = last;
        } else {
            kept.push(last);
        }
    }
    kept
}

/// The length of the polyline through `points`, m (infinite when a value is).
pub fn polyline_length(points: &[(f64, f64)]) -> f64 {
    points.windows(2).map(|w| distance(w[0], w[1])).sum()
}

/// Distance from `(x, y)` to the polyline through `path`, m.
pub fn distance_to_polyline(path: &[(f64, f64)], x: f64, y: f64) -> f64 {
    if let [only] = path {
        return distance(*only, (x, y));
    }
    path.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let (cx, cy) = (b.0 - a.0, b.1 - a.1);
            let l2 = (cx * cx + cy * cy).max(1e-12);
            let f = (((x - a.0) * cx + (y - a.1) * cy) / l2).clamp(0.0, 1.0);
            (a.0 + f * cx - x).hypot(a.1 + f * cy - y)
        })
        .fold(f64::INFINITY, f64::min)
}

fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    (b.0 - a.0).hypot(b.1 - a.1)
}

fn bearing(a: (f64, f64), b: (f64, f64)) -> f64 {
    (b.1 - a.1).atan2(b.0 - a.0)
}

/// The polylines between corners (a corner ends one and starts the next).
fn split_at_corners(points: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    if points.len() < 2 {
        return out;
    }
    let mut current = vec![points[0]];
    for i in 1..points.len() {
        current.push(points[i]);
        if i + 1 < points.len() {
            let turn = wrap(bearing(points[i], points[i + 1]) - bearing(points[i - 1], points[i]));
            if turn.abs() > CORNER_RAD {
                out.push(std::mem::replace(&mut current, vec![points[i]]));
            }
        }
    }
    if current.len() >= 2 {
        out.push(current);
    }
    out
}

/// Samples a polyline every [`SAMPLE_M`] with its heading, curvature and speed limit.
fn sample(points: &[(f64, f64)], speed: f64, settings: &MotionSettings) -> Segment {
    // Cumulative length at each vertex.
    let mut at = vec![0.0];
    for pair in points.windows(2) {
        at.push(at[at.len() - 1] + distance(pair[0], pair[1]));
    }
    let length = at[at.len() - 1];
    let n = ((length / SAMPLE_M).ceil() as usize).max(1);
    let step = length / n as f64;
    let mut samples = Vec::with_capacity(n + 1);
    let mut vertex = 0;
    for i in 0..=n {
        let s = step * i as f64;
        while vertex + 2 < at.len() && at[vertex + 1] < s {
            vertex += 1;
        }
        let span = at[vertex + 1] - at[vertex];
        let f = if span > 0.0 {
            ((s - at[vertex]) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (a, b) = (points[vertex], points[vertex + 1]);
        samples.push(Sample {
            s,
            x: a.0 + (b.0 - a.0) * f,
            y: a.1 + (b.1 - a.1) * f,
            yaw: 0.0,
            kappa: 0.0,
            v_max: speed,
        });
    }
    let last = samples.len() - 1;
    let half = |window: f64| ((window / 2.0 / step).round() as usize).max(1);
    let h = half(HEADING_WINDOW_M);
    for i in 0..=last {
        let (a, b) = (i.saturating_sub(h), (i + h).min(last));
        let yaw = bearing((samples[a].x, samples[a].y), (samples[b].x, samples[b].y));
        samples[i].yaw = yaw;
    }
    let c = half(CURVATURE_WINDOW_M);
    for i in 0..=last {
        let (a, b) = (i.saturating_sub(c), (i + c).min(last));
        let ds = samples[b].s - samples[a].s;
        samples[i].kappa = if ds > 0.0 {
            wrap(samples[b].yaw - samples[a].yaw) / ds
        } else {
            0.0
        };
    }
    let limits = planning_limits(settings.linear);
    let lateral = settings.task.max_lateral_accel_mps2;
    let yaw_rate = settings.angular.speed * YAW_RATE_SHARE;
    for sample in &mut samples {
        let k = sample.kappa.abs();
        if k > 0.0 {
            sample.v_max = sample.v_max.min((lateral / k).sqrt()).min(yaw_rate / k);
        }
        sample.v_max = sample.v_max.min(limits.speed);
    }
    // Brake for every slower stretch ahead (the end's braking is the follower's: it
    // depends on where the vehicle is between samples).
    for i in (0..last).rev() {
        let ds = samples[i + 1].s - samples[i].s;
        let reachable = (samples[i + 1].v_max.powi(2) + 2.0 * limits.decel * ds).sqrt();
        samples[i].v_max = samples[i].v_max.min(reachable);
    }
    Segment { samples }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::moves::tests::settings;
    use std::f64::consts::PI;

    fn circle(radius: f64, spacing: f64) -> Vec<(f64, f64)> {
        let n = (2.0 * PI * radius / spacing).round() as usize;
        (0..=n)
            .map(|i| {
                let a = 2.0 * PI * i as f64 / n as f64 - PI / 2.0;
                (radius * a.cos(), radius + radius * a.sin())
            })
            .collect()
    }

    #[test]
    fn a_curve_of_chords_reads_as_its_curvature_and_limits_the_speed() {
        let s = settings();
        let track = Track::new(&circle(2.0, 0.1), 1.0, &s);
        assert_eq!(track.segments.len(), 1);
        let seg = &track.segments[0];
        assert!(
            (seg.length() - 2.0 * PI * 2.0).abs() < 0.05,
            "{}",
            seg.length()
        );
        let middle = &seg.samples[seg.samples.len() / 2];
        assert!((middle.kappa - 0.5).abs() < 0.02, "{}", middle.kappa);
        // √(0.5 m/s² · 2 m) = 1 m/s, but the yaw rate allows 0.7 · 1 rad/s · 2 m = 1.4,
        // and the profile plans with 95 % of 1 m/s.
        assert!((middle.v_max - 0.95).abs() < 0.03, "{}", middle.v_max);
        assert_eq!(seg.speed_limit(seg.length(), 1.0), 0.0);
        assert!((seg.speed_limit(seg.length() - 0.02, 1.0) - 0.2).abs() < 1e-9);
    }

    #[test]
    fn a_sharp_vertex_splits_and_close_points_are_dropped() {
        let s = settings();
        let points = [
            (0.0, 0.0),
            (0.001, 0.0),
            (1.0, 0.0),
            (1.0, 0.003),
            (1.0, 1.0),
            (0.0, 1.0),
        ];
        let track = Track::new(&points, 0.5, &s);
        assert_eq!(track.segments.len(), 3);
        let ends: Vec<_> = track
            .segments
            .iter()
            .map(|seg| {
                let l = seg.samples.last().expect("samples");
                (l.x, l.y)
            })
            .collect();
        assert_eq!(ends, vec![(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        assert!((track.length() - 3.0).abs() < 1e-9);
        // Three straight metres at 0.5 m/s from rest to rest (2.6 s each) and two quarter
        // turns (2.2 s each).
        let planned = track.planned_s(&s);
        assert!(planned > 10.0 && planned < 13.0, "{planned}");
    }

    #[test]
    fn a_path_of_one_point_or_none_has_no_length() {
        let s = settings();
        assert!(Track::new(&[], 0.5, &s).segments.is_empty());
        assert!(Track::new(&[(1.0, 1.0)], 0.5, &s).segments.is_empty());
        assert!(
            Track::new(&[(1.0, 1.0), (1.0, 1.0)], 0.5, &s)
                .segments
                .is_empty()
        );
        let short = Track::new(&[(1.0, 1.0), (1.05, 1.0)], 0.5, &s);
        assert_eq!(short.segments.len(), 1);
        assert!((short.length() - 0.05).abs() < 1e-9);
    }
}
