//! Protocol dialects: codecs between each protocol's JSON and the core's types.

pub mod adapter;
pub mod device;
pub mod legacy;
pub mod local;
pub mod log_budget;
pub mod mqtt;
pub mod publish;
pub mod request_body;
pub mod requests;
pub mod root;
pub mod ros1;
pub mod ros2;
pub mod rosbridge;
pub mod rtk;
#[cfg(test)]
mod test_core;
pub mod trajectory;

/// Every MQTT dialect's entry point, in the order incoming topics are offered to them.
/// A new dialect adds its module and its entry here; the engine lists none of them.
pub const DIALECTS: &[mqtt::DialectFactory] =
    &[rtk::from_setup, root::from_setup, device::from_setup];

/// Makes a channel's adapter for the vehicle of a name.
pub type AdapterFactory = fn(&str) -> Box<dyn adapter::Adapter>;

/// Every command channel's adapter but the MQTT link's (whose dialects the configuration
/// chooses), made for the vehicle of a name (what a client that asks is told): a new channel
/// adds its adapter here, and the engine routes its source to it.
pub const ADAPTERS: &[AdapterFactory] = &[
    |_| Box::new(local::ADAPTER),
    |_| Box::new(rosbridge::adapter::ADAPTER),
    |vehicle| Box::new(ros1::adapter::Ros1Adapter::new(vehicle)),
    |_| Box::new(ros2::adapter::ADAPTER),
];

/// Most points in one path.
pub const MAX_PATH_POINTS: usize = trajectory::MAX_POINTS;

/// The points of a flat `[x0, y0, x1, y1, ...]` list (root MISSION paths, the local
/// channel's `follow_path`): an even number of finite values, at least one point.
pub fn path_points(flat: &[f64]) -> Result<Vec<(f64, f64)>, String> {
    if flat.is_empty() || !flat.len().is_multiple_of(2) {
        return Err(format!(
            "path must hold x, y pairs: {} values given",
            flat.len()
        ));
    }
    if flat.len() / 2 > MAX_PATH_POINTS {
        return Err(format!(
            "path has {} points, more than {MAX_PATH_POINTS}",
            flat.len() / 2
        ));
    }
    if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
        return Err(format!("path value {i} is not a finite number"));
    }
    Ok(flat.chunks_exact(2).map(|p| (p[0], p[1])).collect())
}

/// A task's speed: a finite number above zero, m/s (the motion limits cap it).
pub fn task_speed(speed: f64) -> Result<f64, String> {
    if speed.is_finite() && speed > 0.0 {
        Ok(speed)
    } else {
        Err(format!("speed must be a number above 0 m/s, not {speed}"))
    }
}
