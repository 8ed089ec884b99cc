//! The trajectory folder, kept off the control task. The engine works on an in-memory
//! mirror, which answers every query at once; each change goes through a bounded queue to a
//! thread that writes the folder (atomically, with fsync) in the order the changes were made.
//! A slow disk therefore delays only the disk. When the queue is full a change is refused
//! with a reason the client sees, never blocking the loop and never half-applied.
//!
//! A success reply means the change is in the mirror and queued; the file follows within
//! the time one write takes. A write that fails is logged and counted; the mirror keeps the
//! change until the next start, which reads the folder again.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::time::Duration;

use crate::runtime::error::{RuntimeError, invalid};

use crate::api::trajectory::{
    DirStore, FailedWrite, MemoryStore, Trajectory, TrajectoryError, TrajectoryStore,
};
use crate::config::VehicleConfig;

/// Changes waiting for the disk before new ones are refused.
pub const QUEUE: usize = 64;
/// What the mirror (and the folder) may hold.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Points in all: 56 bytes each in memory.
    pub points: usize,
    /// Trajectories: each costs its name and a map entry beyond its points.
    pub trajectories: usize,
}

/// The limits of a vehicle's store: about 112 MB of points at most.
pub const LIMITS: Limits = Limits {
    points: 2_000_000,
    trajectories: 10_000,
};

/// One change for the folder.
enum Change {
    Save(Trajectory),
    Delete(String),
    DeleteAll,
}

/// The store the engine uses: the mirror, and the queue to the writer.
pub struct QueuedStore {
    mirror: MemoryStore,
    points: usize,
    limits: Limits,
    changes: SyncSender<Change>,
    /// Writes that failed, told by the writer thread.
    failed: Receiver<FailedWrite>,
}

/// The writer thread, for waiting on it at exit.
pub struct StoreWriter {
    done: Receiver<()>,
    failures: Arc<AtomicU64>,
}

/// The `rtk` dialect's store, its contents as JSON for a recording, and the writer to wait
/// for at exit when a folder is configured.
pub struct OpenedStore {
    /// The store for the engine.
    pub store: Box<dyn TrajectoryStore>,
    /// Its contents at start, for a recording.
    pub snapshot: Option<Vec<u8>>,
    /// The folder's writer.
    pub writer: Option<StoreWriter>,
}

/// The `rtk` dialect's trajectory folder when one is configured; otherwise `fallback`.
pub fn open(
    config: &VehicleConfig,
    fallback: Box<dyn TrajectoryStore>,
) -> Result<OpenedStore, RuntimeError> {
    let Some(dir) = config
        .mqtt
        .as_ref()
        .and_then(|m| m.rtk.as_ref())
        .and_then(|r| r.trajectory_dir.as_ref())
    else {
        return Ok(OpenedStore {
            store: fallback,
            snapshot: None,
            writer: None,
        });
    };
    let (mut store, writer) = spawn(Path::new(dir), QUEUE, LIMITS)
        .map_err(invalid(format!("trajectory folder {dir}")))?;
    let snapshot = serde_json::to_vec(&store.all()?).ok();
    Ok(OpenedStore {
        store: Box::new(store),
        snapshot,
        writer: Some(writer),
    })
}

/// Reads the folder `dir` into a mirror and starts its writer with a queue of `capacity`;
/// saves beyond `limits` are refused.
pub fn spawn(
    dir: &Path,
    capacity: usize,
    limits: Limits,
) -> Result<(QueuedStore, StoreWriter), TrajectoryError> {
    let mut disk = DirStore::open(dir)?;
    let existing = disk.all()?;
    let points = existing.iter().map(|t| t.data.len()).sum();
    let (changes, queue) = sync_channel(capacity);
    let (done_tx, done) = sync_channel(1);
    let (failed_tx, failed) = sync_channel(capacity);
    let failures = Arc::new(AtomicU64::new(0));
    let failure_count = failures.clone();
    std::thread::Builder::new()
        .name("trajectory-writer".into())
        .spawn(move || {
            write_changes(disk, queue, &failure_count, &failed_tx);
            let _ = done_tx.send(());
        })?;
    Ok((
        QueuedStore {
            mirror: MemoryStore::with(existing),
            points,
            limits,
            changes,
            failed,
        },
        StoreWriter { done, failures },
    ))
}

fn write_changes(
    mut disk: DirStore,
    queue: Receiver<Change>,
    failures: &AtomicU64,
    told: &SyncSender<FailedWrite>,
) {
    for change in queue {
        let (command, what, result) = match &change {
            Change::Save(t) => ("save_trajectory", t.name.as_str(), disk.save(t)),
            Change::Delete(name) => ("delete_trajectory", name.as_str(), disk.delete(name)),
            Change::DeleteAll => (
                "delete_all_trajectory",
                "every trajectory",
                disk.delete_all().map(|_| ()),
            ),
        };
        match result {
            // Deleting what a crash or a hand already removed is done.
            Ok(()) | Err(TrajectoryError::NotFound(_)) => {}
            Err(e) => {
                let n = failures.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_power_of_two() {
                    tracing::error!(trajectory = %what, error = %e, failed = n, "trajectory folder write failed; the change is kept in memory only");
                }
                // Told to the client that asked; beyond the queue's bound the log holds it.
                let _ = told.try_send(FailedWrite {
                    command,
                    what: what.to_owned(),
                    reason: e.to_string(),
                });
            }
        }
    }
}

impl QueuedStore {
    fn queue(&self, change: Change) -> Result<(), TrajectoryError> {
        self.changes.try_send(change).map_err(|e| match e {
            TrySendError::Full(_) => TrajectoryError::Busy,
            TrySendError::Disconnected(_) => {
                TrajectoryError::Io(std::io::Error::other("the trajectory writer has stopped"))
            }
        })
    }
}

impl TrajectoryStore for QueuedStore {
    fn all(&mut self) -> Result<Vec<Trajectory>, TrajectoryError> {
        self.mirror.all()
    }

    fn get(&mut self, name: &str) -> Result<Trajectory, TrajectoryError> {
        TrajectoryStore::get(&mut self.mirror, name)
    }

    fn save(&mut self, trajectory: &Trajectory) -> Result<(), TrajectoryError> {
        let existing = self.mirror.get(&trajectory.name).map(|t| t.data.len());
        let count = self.mirror.len();
        if existing.is_none() && count >= self.limits.trajectories {
            return Err(TrajectoryError::TooManyTrajectories(count));
        }
        let replaced = existing.unwrap_or(0);
        let points = self.points - replaced + trajectory.data.len();
        if points > self.limits.points {
            return Err(TrajectoryError::StoreFull {
                stored: self.points - replaced,
                limit: self.limits.points,
            });
        }
        self.queue(Change::Save(trajectory.clone()))?;
        self.points = points;
        self.mirror.save(trajectory)
    }

    fn delete(&mut self, name: &str) -> Result<(), TrajectoryError> {
        let Some(len) = self.mirror.get(name).map(|t| t.data.len()) else {
            return Err(TrajectoryError::NotFound(name.to_owned()));
        };
        self.queue(Change::Delete(name.to_owned()))?;
        self.points -= len;
        self.mirror.delete(name)
    }

    fn delete_all(&mut self) -> Result<usize, TrajectoryError> {
        self.queue(Change::DeleteAll)?;
        self.points = 0;
        self.mirror.delete_all()
    }

    fn failed_writes(&mut self) -> Vec<FailedWrite> {
        self.failed.try_iter().collect()
    }
}

impl StoreWriter {
    /// Waits up to `wait` for every queued change to reach the folder (the engine, and with
    /// it the queue's sender, must be gone). Returns whether they all did.
    pub fn finish(self, wait: Duration) -> bool {
        let finished = !matches!(self.done.recv_timeout(wait), Err(RecvTimeoutError::Timeout));
        if !finished {
            tracing::error!("trajectory changes still unwritten at exit");
        }
        finished && self.failures.load(Ordering::Relaxed) == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::trajectory::Point;

    fn trajectory(name: &str, points: usize) -> Trajectory {
        let p = Point {
            angle: 0.0,
            latitude: 23.0,
            longitude: 113.0,
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
            z: 0.0,
        };
        Trajectory {
            name: name.into(),
            data: vec![p; points],
        }
    }

    fn folder(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("chassisd-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn changes_reach_the_folder_in_order() {
        let dir = folder("queued-order");
        let (mut store, writer) = spawn(&dir, QUEUE, LIMITS).unwrap();
        store.save(&trajectory("a", 3)).unwrap();
        store.save(&trajectory("b", 2)).unwrap();
        store.save(&trajectory("a", 1)).unwrap();
        store.delete("b").unwrap();
        assert!(matches!(
            store.delete("b"),
            Err(TrajectoryError::NotFound(_))
        ));
        assert_eq!(store.all().unwrap(), vec![trajectory("a", 1)]);
        drop(store);
        assert!(writer.finish(Duration::from_secs(5)));
        let mut disk = DirStore::open(&dir).unwrap();
        assert_eq!(disk.all().unwrap(), vec![trajectory("a", 1)]);
        // A new start reads the folder into the mirror.
        let (mut again, writer) = spawn(&dir, QUEUE, LIMITS).unwrap();
        assert_eq!(again.all().unwrap(), vec![trajectory("a", 1)]);
        assert_eq!(again.delete_all().unwrap(), 1);
        drop(again);
        assert!(writer.finish(Duration::from_secs(5)));
        assert_eq!(disk.all().unwrap(), vec![]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_write_that_fails_after_its_answer_is_told_to_the_dialect() {
        use crate::api::mqtt::Dialect;
        let dir = folder("queued-failing");
        let (store, writer) = spawn(&dir, QUEUE, LIMITS).unwrap();
        let mut rtk = crate::api::rtk::RtkDialect::new(Box::new(store), 1 << 20);
        // The folder goes away under the running store (a disk unmounted, a hand): the save
        // is answered from the mirror, then its write fails.
        std::fs::remove_dir_all(&dir).unwrap();
        let save = serde_json::json!({
            "cmd": "save_trajectory",
            "cmd_type": "trajectory_control",
            "data": {"name": "row", "data": [
                {"angle": 0.0, "latitude": 23.0, "longitude": 113.0, "x": 0.0, "y": 0.0, "yaw": 0.0, "z": 0.0}
            ]}
        });
        struct NoCore;
        impl crate::api::mqtt::CoreAccess for NoCore {
            fn pose_report(&self) -> crate::vehicle::PoseReport {
                crate::vehicle::PoseReport::default()
            }

            fn command(
                &mut self,
                _: crate::vehicle::Command,
            ) -> Result<(), crate::vehicle::chassis::CommandRejected> {
                Ok(())
            }
        }
        let mut core = NoCore;
        let mut out = Vec::new();
        rtk.on_message(
            crate::time::Timestamp::from_micros(0),
            "mqtt_control",
            save.to_string().as_bytes(),
            &mut core,
            &mut out,
        );
        let answers: Vec<String> = out
            .iter()
            .map(|p| String::from_utf8_lossy(&p.payload).into_owned())
            .collect();
        assert!(
            answers[0].contains("save_trajectory_success"),
            "{answers:?}"
        );
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        let mut later = Vec::new();
        while later.is_empty() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
            rtk.on_status(
                &crate::vehicle::VehicleStatus::default(),
                &mut core,
                &mut later,
            );
            later.retain(|p| p.topic == "feedback");
        }
        let told = String::from_utf8_lossy(&later[0].payload).into_owned();
        assert!(
            told.contains("save_trajectory_failse") && told.contains("row"),
            "{told}"
        );
        drop(rtk);
        assert!(
            !writer.finish(Duration::from_secs(5)),
            "the failure counted"
        );
    }

    #[test]
    fn a_full_queue_refuses_without_changing_the_mirror() {
        let dir = folder("queued-full");
        let (mut store, writer) = spawn(&dir, 1, LIMITS).unwrap();
        // The writer cannot keep up with a burst: at some point a save is refused, and the
        // refused one is in neither the mirror nor the folder.
        let mut refused = None;
        for i in 0..10_000 {
            match store.save(&trajectory(&format!("t{i}"), 1)) {
                Ok(()) => {}
                Err(TrajectoryError::Busy) => {
                    refused = Some(format!("t{i}"));
                    break;
                }
                Err(e) => panic!("{e}"),
            }
        }
        let refused = refused.expect("a save refused while the queue is full");
        let names: Vec<String> = store.all().unwrap().into_iter().map(|t| t.name).collect();
        assert!(!names.contains(&refused));
        drop(store);
        assert!(writer.finish(Duration::from_secs(30)));
        let mut on_disk: Vec<String> = DirStore::open(&dir)
            .unwrap()
            .all()
            .unwrap()
            .into_iter()
            .map(|t| t.name)
            .collect();
        let mut expected = names;
        on_disk.sort();
        expected.sort();
        assert_eq!(on_disk, expected);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_store_is_bounded_in_points_and_trajectories() {
        let dir = folder("queued-bound");
        let limits = Limits {
            points: 20,
            trajectories: 3,
        };
        let (mut store, writer) = spawn(&dir, QUEUE, limits).unwrap();
        let half = 10;
        store.save(&trajectory("a", half)).unwrap();
        store.save(&trajectory("b", half)).unwrap();
        assert!(matches!(
            store.save(&trajectory("c", 1)),
            Err(TrajectoryError::StoreFull { .. })
        ));
        // Replacing one counts only the difference.
        store.save(&trajectory("b", half - 1)).unwrap();
        store.save(&trajectory("c", 1)).unwrap();
        store.delete("a").unwrap();
        store.save(&trajectory("d", half)).unwrap();
        // Three trajectories: a fourth name is refused, a replacement is not.
        assert!(matches!(
            store.save(&trajectory("e", 0)),
            Err(TrajectoryError::TooManyTrajectories(3))
        ));
        store.save(&trajectory("c", 0)).unwrap();
        drop(store);
        assert!(writer.finish(Duration::from_secs(5)));
        std::fs::remove_dir_all(&dir).ok();
    }
}
