//! The async edges: the tasks and threads that move bytes between the engine and the world.
//!
//! - [`drivers`]: the devices' ports (serial, SocketCAN), read and written;
//! - [`links`]: the clients' protocols (MQTT and its embedded broker, ROS1, rosbridge over
//!   WebSocket, NTRIP, standard input);
//! - [`modes`]: one per way of running (live, simulation, listen-only recording, check, CAN
//!   device simulation), each wiring drivers and links to the engine;
//! - the plumbing beside them: clocks, the recorder and status threads, logging to the
//!   journal, systemd notification, panic containment, the allocator's tuning.

pub mod child_process;
pub mod clock;
pub mod descriptors;
pub mod drivers;
pub mod error;
pub mod foreign_log;
pub mod heap;
pub mod host;
pub mod journal;
pub mod links;
pub mod listeners;
pub mod logging;
pub mod lossy;
pub mod mcap_sink;
pub mod modes;
pub mod notify;
pub mod outage_log;
pub mod panics;
pub mod progress;
pub mod recorder;
pub mod refusals;
pub mod session;
pub mod status_out;
pub mod stderr;
pub mod trajectory_writer;
pub mod zones_writer;
