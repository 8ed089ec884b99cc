//! Writes the zones back to their file after an edit, off the control loop: the latest set
//! waits in a slot that a thread of its own takes, and each write is atomic (a temporary
//! file, fsync, rename), so a crash leaves the old zones or the new ones. Edits that come
//! faster than the disk keep only the latest; on drop the last one is written before the
//! thread ends.

use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

use crate::api::trajectory::write_atomically;

/// The slot: the zones to write next, and whether the writer is closing.
type Slot = Arc<(Mutex<(Option<String>, bool)>, Condvar)>;

/// The writer of one zones file.
pub struct ZonesWriter {
    slot: Slot,
    thread: Option<JoinHandle<()>>,
}

impl ZonesWriter {
    /// A writer of `file`, its thread started.
    pub fn start(file: PathBuf) -> std::io::Result<Self> {
        let slot: Slot = Arc::new((Mutex::new((None, false)), Condvar::new()));
        let theirs = slot.clone();
        let thread = std::thread::Builder::new()
            .name("zones-writer".into())
            .spawn(move || write_until_closed(&theirs, &file))?;
        Ok(Self {
            slot,
            thread: Some(thread),
        })
    }

    /// Queues `geojson` to be written, replacing any not written yet.
    pub fn write(&self, geojson: String) {
        let (lock, ready) = &*self.slot;
        if let Ok(mut slot) = lock.lock() {
            slot.0 = Some(geojson);
            ready.notify_one();
        }
    }
}

impl Drop for ZonesWriter {
    fn drop(&mut self) {
        let (lock, ready) = &*self.slot;
        if let Ok(mut slot) = lock.lock() {
            slot.1 = true;
            ready.notify_one();
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn write_until_closed(slot: &Slot, file: &std::path::Path) {
    let dir = file
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), PathBuf::from);
    let (lock, ready) = &**slot;
    loop {
        let (next, closing) = {
            let Ok(mut guard) = lock.lock() else {
                return;
            };
            while guard.0.is_none() && !guard.1 {
                guard = match ready.wait(guard) {
                    Ok(g) => g,
                    Err(_) => return,
                };
            }
            (guard.0.take(), guard.1)
        };
        if let Some(text) = next {
            match write_atomically(&dir, file, text.as_bytes()) {
                Ok(()) => tracing::info!(file = %file.display(), "zones written"),
                Err(e) => tracing::error!(
                    file = %file.display(),
                    error = %e,
                    "cannot write the zones file; the edit holds until chassisd stops"
                ),
            }
        }
        if closing {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_latest_zones_are_written_whole_before_the_writer_ends() {
        let dir = std::env::temp_dir().join(format!("zones-writer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let file = dir.join("zones.geojson");
        let writer = ZonesWriter::start(file.clone()).expect("started");
        for n in 0..50 {
            writer.write(format!("{{\"n\": {n}}}"));
        }
        drop(writer);
        assert_eq!(
            std::fs::read_to_string(&file).expect("written"),
            "{\"n\": 49}"
        );
        // No temporary file is left beside it.
        let names: Vec<_> = std::fs::read_dir(&dir)
            .expect("listed")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
