//! A CiA 402 drive on its interface: its node, the mapping of its axes to wheels, unit
//! conversion between motor and wheel, and encoder unwrapping; or the blade's drive, which
//! runs at its speed while the cutter is on.

use std::f64::consts::TAU;
use std::time::Duration;

use super::device::{CanDevice, DriveCommand, Heard};
use crate::config::VehicleConfig;
use crate::config::chassis::{CanBusConfig, Wheel, WheelConfig, WheelsConfig};
use crate::config::mission::Cutter;
use crate::devices::can::Frame;
use crate::devices::canopen::NodeId;
use crate::devices::cia402::node::{DriveFault, DriveNode, NodeSettings, Phase};
use crate::time::Timestamp;
use crate::vehicle::chassis::{ChassisFeedback, DriveSummary, WheelFeedback};

/// Unwraps a 32-bit encoder count into a continuous one.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Unwrap {
    last: Option<i32>,
    total: i64,
}

impl Unwrap {
    pub(super) fn update(&mut self, raw: i32) -> i64 {
        match self.last {
            None => self.total = i64::from(raw),
            Some(last) => self.total += i64::from(raw.wrapping_sub(last)),
        }
        self.last = Some(raw);
        self.total
    }
}

#[derive(Debug, Clone)]
struct Axis {
    wheel: Wheel,
    /// Motor revolutions per wheel revolution, signed by the wheel's direction.
    ratio: f64,
    unwrap: Unwrap,
}

/// One `[[drive]]`.
#[derive(Debug, Clone)]
pub struct Drive {
    name: String,
    node: DriveNode,
    axes: Vec<Axis>,
    /// The blade drive's motor speed while the cutter is on, r/min (`None`: a wheel drive).
    blade_rpm: Option<f64>,
    /// Its interface is listen-only: the node is watched, never started or commanded.
    listen_only: bool,
    started: bool,
}

/// The `[[drive]]`s on `bus`, in the configuration's order.
pub fn build(config: &VehicleConfig, bus: &CanBusConfig) -> Vec<Box<dyn CanDevice>> {
    let wheels = config.wheels.unwrap_or(WheelsConfig {
        left: WheelConfig {
            direction: 1,
            gear_ratio: 1.0,
        },
        right: WheelConfig {
            direction: 1,
            gear_ratio: 1.0,
        },
    });
    let cutter = config.cutter.as_ref().and_then(|c| c.cutter().ok());
    let blade_rpm = |name: &str| match &cutter {
        Some(Cutter::Drive { name: blade, rpm }) if blade == name => Some(*rpm),
        _ => None,
    };
    config
        .drive
        .iter()
        .filter(|d| d.bus == bus.interface)
        .filter_map(|d| {
            let profile = d.profile.get()?.clone();
            let settings = NodeSettings {
                node: NodeId::new(d.node)?,
                heartbeat_producer_ms: d.heartbeat_ms,
                heartbeat_timeout: Duration::from_millis(d.heartbeat_timeout_ms),
                sdo_timeout: Duration::from_millis(d.sdo_timeout_ms),
                sdo_retries: d.sdo_retries,
                boot_timeout: Duration::from_millis(d.boot_timeout_ms),
                enable_timeout: Duration::from_millis(d.enable_timeout_ms),
                feedback_timeout: d.feedback_timeout(&profile),
                reset_attempts: d.reset_attempts,
                reset_wait: Duration::from_millis(d.reset_wait_ms),
                master_node: NodeId::new(bus.master_node)?,
                master_timeout: Duration::from_millis(d.master_timeout_ms),
                sync_period: Duration::from_millis(bus.sync_ms),
            };
            let mut node = DriveNode::new(settings, profile);
            node.set_monitor(bus.listen_only);
            let axes = d
                .wheels
                .iter()
                .map(|w| {
                    let wc = match w {
                        Wheel::Left => wheels.left,
                        Wheel::Right => wheels.right,
                    };
                    Axis {
                        wheel: *w,
                        ratio: wc.gear_ratio * f64::from(wc.direction),
                        unwrap: Unwrap::default(),
                    }
                })
                .collect();
            Some(Box::new(Drive {
                name: d.name.clone(),
                node,
                axes,
                blade_rpm: blade_rpm(&d.name),
                listen_only: bus.listen_only,
                started: false,
            }) as Box<dyn CanDevice>)
        })
        .collect()
}

impl CanDevice for Drive {
    fn on_frame(&mut self, t: Timestamp, frame: &Frame, out: &mut Vec<Frame>) -> Heard {
        self.node.on_frame(t, frame, out);
        Heard::Nothing
    }

    fn on_link(&mut self, t: Timestamp, up: bool, out: &mut Vec<Frame>) {
        if !up {
            self.node.link_down();
        } else if self.started && !self.listen_only {
            self.node.link_up(t, out);
        }
    }

    fn poll(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        if !self.started && !self.listen_only {
            self.started = true;
            self.node.start(t, out);
        }
        // The command goes out with the flush that follows this tick's command.
        self.node.poll_timers(t, out);
    }

    fn command(&mut self, t: Timestamp, command: &DriveCommand) {
        if command.reset_faults && self.node.fault().is_some() && !self.node.reset_fault(t) {
            tracing::warn!(drive = %self.name, "fault cannot be reset yet");
        }
        if let Some(blade) = self.blade_rpm {
            let rpm = if command.cutter_on { blade } else { 0.0 };
            self.node.command(t, command.goal, &[rpm]);
            return;
        }
        let rpm: Vec<f64> = self
            .axes
            .iter()
            .map(|axis| {
                let wheel = match axis.wheel {
                    Wheel::Left => command.left_rad_s,
                    Wheel::Right => command.right_rad_s,
                };
                wheel / TAU * 60.0 * axis.ratio
            })
            .collect();
        self.node.command(t, command.goal, &rpm);
    }

    fn flush(&mut self, t: Timestamp, out: &mut Vec<Frame>) {
        self.node.flush_command(t, out);
    }

    fn shut_down(&mut self, out: &mut Vec<Frame>) {
        self.node.shut_down(out);
    }

    fn stop_frames(&self) -> Vec<Frame> {
        self.node.stop_frames()
    }

    fn report(&mut self, fb: &mut ChassisFeedback) {
        let units = self.node.profile().units;
        for (a, axis) in self.axes.iter_mut().enumerate() {
            let Some(raw) = self.node.axes().get(a).copied() else {
                continue;
            };
            let wheel = WheelFeedback {
                velocity_rad_s: raw.velocity.map(|v| {
                    f64::from(v) / units.actual_velocity_per_rpm / 60.0 * TAU / axis.ratio
                }),
                angle_rad: raw.position.map(|p| {
                    axis.unwrap.update(p) as f64 / units.counts_per_rev * TAU / axis.ratio
                }),
                received: raw.rx,
                velocity_received: raw.velocity_rx,
            };
            match axis.wheel {
                Wheel::Left => fb.left = wheel,
                Wheel::Right => fb.right = wheel,
            }
        }
        let fault = self.node.fault();
        fb.drives.push(DriveSummary {
            name: self.name.clone(),
            ready: self.node.is_ready(),
            running: self.node.phase() == Phase::Running,
            enabled: self.node.is_enabled(),
            fault: fault.map(|f| f.to_string()),
            heartbeat_lost: fault == Some(DriveFault::HeartbeatLost),
            resetting: self.node.is_resetting(),
        });
    }

    fn is_drive(&self) -> bool {
        true
    }

    fn node(&self) -> Option<(&str, &DriveNode)> {
        Some((&self.name, &self.node))
    }
}
