//! The safety envelope's messages: the zones as `visualization_msgs/MarkerArray` (what rviz
//! and Foxglove draw, and the live page), and the vehicle's margin as a
//! `diagnostic_msgs/DiagnosticStatus` (the gate, the nearest zone and its clearance against
//! what the run-time check keeps: σ and the braking way).

use serde_json::{Value, json};

use super::parts::{OK, WARN, diagnostic, header};
use crate::api::ros1::MAP_FRAME;
use crate::time::Timestamp;
use crate::vehicle::envelope::EnvelopeStatus;
use crate::zones::ZoneKind;
use crate::zones::local::ZoneOutline;

/// Marker types and actions of visualization_msgs/Marker.
const LINE_LIST: u8 = 5;
const ADD: u8 = 0;
const DELETE_ALL: u8 = 3;
/// The zones' lines are drawn this wide, m.
const LINE_WIDTH_M: f64 = 0.05;

/// Metres to the millimetre: what a drawing needs, in a third of the digits.
fn mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// A zone kind's colour (r, g, b).
fn colour(kind: ZoneKind) -> (f64, f64, f64) {
    match kind {
        ZoneKind::Boundary => (0.16, 0.6, 0.25),
        ZoneKind::KeepOut => (0.8, 0.1, 0.1),
        ZoneKind::Wall => (0.85, 0.45, 0.0),
    }
}

/// `/zones` (visualization_msgs/MarkerArray): a DELETEALL first (so a removed zone goes
/// from a viewer too), then one LINE_LIST marker per zone in `map`: `ns` its kind, `id` its
/// id (the `shapeId` ROS1 `/set_shape` removes it by), `text` its name, `points` in pairs,
/// each a segment of its outline.
pub fn zones(t: Timestamp, outlines: &[ZoneOutline]) -> Value {
    let clear = marker(t, json!({"action": DELETE_ALL}));
    let markers = outlines.iter().map(|zone| {
        let points: Vec<Value> = zone
            .lines
            .iter()
            .flat_map(|line| line.windows(2))
            .flat_map(|pair| pair.iter())
            .map(|&(x, y)| json!({"x": mm(x), "y": mm(y), "z": 0.0}))
            .collect();
        let (r, g, b) = colour(zone.kind);
        marker(
            t,
            json!({
                "ns": zone.kind.name(),
                "id": zone.id,
                "scale": {"x": LINE_WIDTH_M, "y": 0.0, "z": 0.0},
                "color": {"r": r, "g": g, "b": b, "a": 1.0},
                "points": points,
                "text": zone.name,
            }),
        )
    });
    json!({"markers": std::iter::once(clear).chain(markers).collect::<Vec<_>>()})
}

/// A visualization_msgs/Marker in `map` with every field of ROS 2 Jazzy's definition (a
/// LINE_LIST added, the rest empty), `fields` put over them: the ROS 2 node serialises it
/// through that type, and a rosbridge client ignores what it does not know.
fn marker(t: Timestamp, fields: Value) -> Value {
    let mut marker = json!({
        "header": header(t, MAP_FRAME),
        "ns": "",
        "id": 0,
        "type": LINE_LIST,
        "action": ADD,
        "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                 "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "scale": {"x": 0.0, "y": 0.0, "z": 0.0},
        "color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0},
        "lifetime": {"sec": 0, "nanosec": 0},
        "frame_locked": false,
        "points": [],
        "colors": [],
        "texture_resource": "",
        "texture": {"header": header(t, ""), "format": "", "data": []},
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": {"filename": "", "data": []},
        "mesh_use_embedded_materials": false,
    });
    if let (Value::Object(all), Value::Object(given)) = (&mut marker, fields) {
        all.extend(given);
    }
    marker
}

/// The envelope's diagnostic status (`/safety_envelope`, and in `/diagnostics`): OK while
/// the gate is open and the nearest zone lies beyond the margin; WARN while the gate is
/// closed (autonomous work and the blade pause), the vehicle is not placed, or a zone lies
/// within the margin (the run-time check stops a way towards it).
pub fn status(e: &EnvelopeStatus) -> Value {
    let margin = e.margin_m();
    let within = e
        .nearest
        .as_ref()
        .zip(margin)
        .is_some_and(|(n, m)| n.clearance_m < m);
    let gate = match &e.gate_closed {
        None => "gate open".to_owned(),
        Some(reason) => format!("gate closed: {reason}"),
    };
    let place = match (&e.nearest, margin) {
        (Some(n), Some(m)) => format!(
            "{:.2} m from the {} zone {:?}, keeping {m:.3} m",
            n.clearance_m,
            n.kind.name(),
            n.name
        ),
        (None, Some(_)) => "no zones".to_owned(),
        (_, None) => "not placed in the map yet".to_owned(),
    };
    let level = if e.gate_closed.is_some() || margin.is_none() || within {
        WARN
    } else {
        OK
    };
    let metres = |v: Option<f64>| v.map_or_else(|| "unknown".to_owned(), |v| format!("{v:.3}"));
    diagnostic(
        level,
        "safety envelope",
        &format!("{gate}; {place}"),
        &[
            (
                "gate",
                if e.gate_closed.is_some() {
                    "closed"
                } else {
                    "open"
                }
                .into(),
            ),
            (
                "gate_reason",
                e.gate_closed
                    .as_ref()
                    .map_or_else(String::new, ToString::to_string),
            ),
            (
                "nearest_zone",
                e.nearest
                    .as_ref()
                    .map_or_else(String::new, |n| n.name.clone()),
            ),
            (
                "nearest_kind",
                e.nearest
                    .as_ref()
                    .map_or_else(String::new, |n| n.kind.name().to_owned()),
            ),
            (
                "clearance_m",
                metres(e.nearest.as_ref().map(|n| n.clearance_m)),
            ),
            ("margin_m", metres(margin)),
            ("sigma_m", metres(e.sigma_m)),
            ("braking_m", format!("{:.3}", e.braking_m)),
            ("footprint_m", format!("{:.3}", e.footprint_m)),
            ("zones", e.zones.as_ref().map_or(0, |z| z.len()).to_string()),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::gate::GateReason;
    use crate::vehicle::zones::NearestZone;

    fn outline(id: u32, kind: ZoneKind, name: &str, lines: Vec<Vec<(f64, f64)>>) -> ZoneOutline {
        ZoneOutline {
            id,
            name: name.into(),
            kind,
            lines,
        }
    }

    #[test]
    fn zones_are_one_line_list_each_after_a_delete_all() {
        let square = vec![
            (4.0, -1.0),
            (6.0, -1.0),
            (6.0, 1.0),
            (4.0, 1.0),
            (4.0, -1.0),
        ];
        let hole = vec![(4.5, -0.5), (5.0, -0.5), (5.0, 0.0), (4.5, -0.5)];
        let msg = zones(
            Timestamp::from_nanos(1),
            &[
                outline(3, ZoneKind::KeepOut, "pond", vec![square, hole]),
                outline(
                    7,
                    ZoneKind::Wall,
                    "fence",
                    vec![vec![(-3.0, -5.0), (-3.0, 5.000_000_4)]],
                ),
            ],
        );
        let markers = msg["markers"].as_array().unwrap();
        assert_eq!(markers.len(), 3);
        assert_eq!(markers[0]["action"], DELETE_ALL);
        let pond = &markers[1];
        assert_eq!(
            (pond["ns"].as_str(), pond["id"].as_u64()),
            (Some("keep_out"), Some(3))
        );
        assert_eq!(pond["text"], "pond");
        assert_eq!(pond["type"], LINE_LIST);
        assert_eq!(pond["header"]["frame_id"], "map");
        // Four segments of the square, three of the hole: two points each.
        assert_eq!(pond["points"].as_array().unwrap().len(), 14);
        assert_eq!(pond["points"][1], json!({"x": 6.0, "y": -1.0, "z": 0.0}));
        let fence = &markers[2];
        assert_eq!(fence["ns"], "wall");
        assert_eq!(fence["points"][1]["y"], 5.0, "to the millimetre");
        assert_ne!(pond["color"], fence["color"]);
    }

    fn envelope() -> EnvelopeStatus {
        EnvelopeStatus {
            gate_closed: None,
            zones: Some(vec![outline(1, ZoneKind::KeepOut, "pond", vec![])].into()),
            nearest: Some(NearestZone {
                name: "pond".into(),
                kind: ZoneKind::KeepOut,
                clearance_m: 1.5,
            }),
            footprint_m: 0.5,
            sigma_m: Some(0.02),
            braking_m: 0.3,
        }
    }

    fn value<'a>(msg: &'a Value, key: &str) -> &'a str {
        msg["values"]
            .as_array()
            .unwrap()
            .iter()
            .find(|v| v["key"] == key)
            .and_then(|v| v["value"].as_str())
            .unwrap_or_else(|| panic!("{key} in {msg}"))
    }

    #[test]
    fn the_margin_is_sigma_and_the_braking_way_against_the_nearest_zone() {
        let e = envelope();
        let msg = status(&e);
        assert_eq!(msg["level"], OK);
        assert_eq!(msg["name"], "chassisd: safety envelope");
        assert_eq!(
            msg["message"],
            "gate open; 1.50 m from the keep_out zone \"pond\", keeping 0.320 m"
        );
        assert_eq!(value(&msg, "margin_m"), "0.320");
        assert_eq!(value(&msg, "clearance_m"), "1.500");
        assert_eq!(value(&msg, "zones"), "1");
        // Nearer than the margin: a warning.
        let near = EnvelopeStatus {
            nearest: Some(NearestZone {
                clearance_m: 0.2,
                ..e.nearest.clone().unwrap()
            }),
            ..e.clone()
        };
        assert_eq!(status(&near)["level"], WARN);
        let closed = EnvelopeStatus {
            gate_closed: Some(GateReason::NoFix),
            ..e.clone()
        };
        let msg = status(&closed);
        assert_eq!(msg["level"], WARN);
        assert!(
            msg["message"]
                .as_str()
                .unwrap()
                .starts_with("gate closed: no valid GNSS fix")
        );
        assert_eq!(value(&msg, "gate"), "closed");
        let unplaced = EnvelopeStatus {
            sigma_m: None,
            nearest: None,
            zones: None,
            ..e
        };
        let msg = status(&unplaced);
        assert_eq!(msg["level"], WARN);
        assert_eq!(value(&msg, "margin_m"), "unknown");
        assert!(
            msg["message"]
                .as_str()
                .unwrap()
                .ends_with("not placed in the map yet")
        );
    }
}
