//! A helper process talked to in JSON lines (the ROS nodes' processes): started with its
//! settings as the first line of its standard input, then a line per message each way.
//! Both ends are here: [`ChildPipes`] in chassisd, [`read_from_parent`] and
//! [`write_to_parent`] in the helper.
//! Sending never blocks the sender: a process that does not keep up loses lines, counted by
//! its owner. What it says comes back parsed, a line it should not have said logged once
//! each and skipped.

use std::time::Instant;

use serde::Serialize;
use serde::de::DeserializeOwned;
use tokio::io::{AsyncWriteExt, BufReader};
use tokio::process::{Child, ChildStdout, Command};
use tokio::sync::mpsc;

use crate::runtime::child_process;
use crate::runtime::links::input_lines::{InputLine, InputLines};

/// A running helper process and the ends of its pipes.
pub struct ChildPipes<Up> {
    /// The process (killed when this is dropped).
    pub child: Child,
    /// Lines to its standard input.
    pub down: mpsc::Sender<String>,
    /// What it said.
    pub up: mpsc::Receiver<Up>,
    /// When it started.
    pub started: Instant,
}

impl<Up: DeserializeOwned + Send + 'static> ChildPipes<Up> {
    /// Starts `subcommand` of `exe` and hands it `settings`; `queue` lines wait each way
    /// and no line longer than `max_line` is taken from it. `what` names it in the log.
    pub async fn start(
        exe: &std::path::Path,
        subcommand: &str,
        settings: &str,
        queue: usize,
        max_line: usize,
        what: &'static str,
    ) -> std::io::Result<Self> {
        let mut child = Command::from(child_process::helper_command(exe, subcommand))
            .kill_on_drop(true)
            .spawn()?;
        let (Some(mut stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            return Err(std::io::Error::other("its pipes were not set up"));
        };
        stdin.write_all(format!("{settings}\n").as_bytes()).await?;
        let (down, mut down_rx) = mpsc::channel::<String>(queue);
        tokio::spawn(async move {
            while let Some(mut line) = down_rx.recv().await {
                line.push('\n');
                if stdin.write_all(line.as_bytes()).await.is_err() {
                    return;
                }
            }
        });
        let (up_tx, up) = mpsc::channel(queue);
        tokio::spawn(read_lines(stdout, up_tx, max_line, what));
        Ok(Self {
            child,
            down,
            up,
            started: Instant::now(),
        })
    }
}

/// Reads the process's lines until its standard output closes.
async fn read_lines<Up: DeserializeOwned>(
    stdout: ChildStdout,
    up: mpsc::Sender<Up>,
    max_line: usize,
    what: &'static str,
) {
    let mut lines = InputLines::new(BufReader::new(stdout), max_line);
    while let Ok(Some(line)) = lines.next().await {
        let message = match line {
            InputLine::Text(text) => serde_json::from_str::<Up>(&text).map_err(|e| e.to_string()),
            other => Err(format!("{other:?}")),
        };
        match message {
            Ok(message) => {
                if up.send(message).await.is_err() {
                    return;
                }
            }
            Err(e) => tracing::error!(error = %e, "{what}'s process: a line not understood"),
        }
    }
}

/// In the helper process `what`: reads chassisd's lines (at most `max_line` bytes each) into
/// `to`; a line not understood is logged and skipped, and the end of standard input
/// (chassisd gone) ends the process.
pub async fn read_from_parent<T: DeserializeOwned>(
    to: mpsc::Sender<T>,
    max_line: usize,
    what: &'static str,
) {
    let mut lines = InputLines::new(BufReader::new(tokio::io::stdin()), max_line);
    loop {
        match lines.next().await {
            Ok(Some(InputLine::Text(text))) => match serde_json::from_str::<T>(&text) {
                Ok(message) => {
                    if to.send(message).await.is_err() {
                        return;
                    }
                }
                Err(e) => {
                    tracing::error!(error = %e, "{what}: a line from chassisd not understood")
                }
            },
            Ok(Some(other)) => tracing::error!(?other, "{what}: a line from chassisd not taken"),
            Ok(None) | Err(_) => std::process::exit(0),
        }
    }
}

/// In a helper process: writes `up`'s messages to chassisd, a line each; a closed pipe
/// (chassisd gone) ends the process.
pub async fn write_to_parent<T: Serialize>(mut up: mpsc::Receiver<T>) {
    let mut stdout = tokio::io::stdout();
    while let Some(message) = up.recv().await {
        let Ok(mut line) = serde_json::to_vec(&message) else {
            continue;
        };
        line.push(b'\n');
        if stdout.write_all(&line).await.is_err() || stdout.flush().await.is_err() {
            std::process::exit(0);
        }
    }
}
