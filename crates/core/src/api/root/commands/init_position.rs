//! INIT_POSITION (0 on `cmd/navigation`): sets the pose; acked, then notified as done.

use serde_json::Value;

use super::{Context, Done};
use crate::api::requests::quaternion_yaw;
use crate::api::root::error::RootError;
use crate::vehicle::Command;

/// A planar pose: position in the map frame (m) and yaw (rad).
#[derive(Debug, PartialEq)]
struct InitPosition {
    x: f64,
    y: f64,
    yaw: f64,
}

impl InitPosition {
    /// `[x, y, z, qx, qy, qz, qw]`: a position and an orientation quaternion, whose norm must
    /// lie within 0.5–1.5 (z is ignored on a planar vehicle).
    fn parse(data: &Value) -> Result<Self, RootError> {
        let numbers: Option<Vec<f64>> = data
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect());
        let Some([x, y, _z, qx, qy, qz, qw]) = numbers
            .filter(|n| data.as_array().is_some_and(|a| a.len() == n.len()))
            .and_then(|n| <[f64; 7]>::try_from(n).ok())
        else {
            return Err(RootError::invalid(
                "data must be [x, y, z, qx, qy, qz, qw]: a position and an orientation quaternion",
            ));
        };
        match quaternion_yaw([qx, qy, qz, qw]) {
            Some(yaw) if x.is_finite() && y.is_finite() => Ok(Self { x, y, yaw }),
            _ => Err(RootError::invalid(
                "values must be finite, the quaternion of unit length",
            )),
        }
    }
}

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    let InitPosition { x, y, yaw } = InitPosition::parse(data)?;
    cx.core.command(Command::SetPose { x, y, yaw })?;
    Ok(Done::Finished)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_pose_is_seven_numbers_with_a_unit_quaternion() {
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let pose = InitPosition::parse(&json!([1.0, 2.0, 9.0, 0.0, 0.0, half, half])).unwrap();
        assert!(
            (pose.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9,
            "{pose:?}"
        );
        for bad in [
            json!([1.0, 2.0, 0.0, 0.0, 0.0, 0.0]),
            json!([1.0, 2.0, 0.0, 0.0, 0.0, 0.0, "1"]),
            json!([1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 3.0]),
            json!({"x": 1}),
        ] {
            assert_eq!(InitPosition::parse(&bad).unwrap_err().code(), 1, "{bad}");
        }
    }
}
