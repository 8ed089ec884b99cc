//! The dialogue with a u-blox receiver that `check` holds: MON-VER to identify it, and,
//! when asked, CFG-VALSET of what chassisd reads with a CFG-VALGET read-back.
//!
//! The receiver goes on streaming its messages meanwhile; the answers are picked out of
//! that stream by the same framer the daemon uses.

use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

use crate::devices::gnss::ubx::config::{self, Layers, Port, Wanted};
use crate::devices::gnss::ubx::{self, MonVer, UbxMessage};
use crate::devices::gnss::{Frame, GnssFramer};

/// How long the receiver may take to answer a poll, per attempt ...
const ANSWER_WAIT: Duration = Duration::from_millis(1000);
/// ... and how many attempts a MON-VER poll gets (the first may cross a busy output).
const POLL_ATTEMPTS: u32 = 2;
/// The first protocol version with CFG-VALSET (u-blox 9 and later).
const FIRST_VALSET_PROTOCOL: f64 = 27.0;

/// Why the receiver was not configured: what happened, and what to do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// What happened.
    pub reason: String,
    /// What to do about it.
    pub fix: String,
}

fn refusal(reason: impl Into<String>, fix: impl Into<String>) -> Refusal {
    Refusal {
        reason: reason.into(),
        fix: fix.into(),
    }
}

/// A receiver's port as the dialogue sees it.
pub struct Dialogue<S> {
    io: S,
    framer: GnssFramer,
    buf: Vec<u8>,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Dialogue<S> {
    /// A dialogue over `io`.
    pub fn new(io: S) -> Self {
        Self {
            io,
            framer: GnssFramer::new(),
            buf: vec![0; 4096],
        }
    }

    /// Asks MON-VER until the receiver answers.
    pub async fn identify(&mut self) -> Result<MonVer, Refusal> {
        for _ in 0..POLL_ATTEMPTS {
            self.send(&config::mon_ver_poll()).await?;
            let answer = self
                .await_message(ANSWER_WAIT, |m| match m {
                    UbxMessage::MonVer(v) => Some(v),
                    _ => None,
                })
                .await?;
            if let Some(version) = answer {
                return Ok(version);
            }
        }
        Err(refusal(
            format!(
                "no answer to MON-VER in {:.0} s",
                ANSWER_WAIT.as_secs_f64() * f64::from(POLL_ATTEMPTS)
            ),
            "is this a u-blox receiver, and does this port take UBX input \
             (CFG-*INPROT-UBX)? Else set gnss.receiver to \"nmea\"",
        ))
    }

    /// Sets what chassisd reads on the receiver's `port` in `layers`, and reads it back.
    /// `version` (from [`Self::identify`]) rules out receivers older than CFG-VALSET.
    pub async fn configure(
        &mut self,
        version: &MonVer,
        port: Port,
        layers: Layers,
    ) -> Result<Vec<Wanted>, Refusal> {
        let protocol = version
            .protocol()
            .and_then(|p| p.trim().parse::<f64>().ok());
        if protocol.is_none_or(|p| p < FIRST_VALSET_PROTOCOL) {
            return Err(refusal(
                format!(
                    "protocol {} predates CFG-VALSET (u-blox 9, protocol 27, and later)",
                    version.protocol().unwrap_or("(not stated)")
                ),
                "enable NAV-PVT (and NAV-RELPOSNED on a moving base) with u-center's CFG-MSG; \
                 chassisd reads what the receiver sends",
            ));
        }
        let wanted = config::wanted(port);
        let items: Vec<config::Item> = wanted.iter().map(|w| w.item).collect();
        let valset = config::valset(layers, &items).map_err(|e| refusal(e.to_string(), ""))?;
        self.send(&valset).await?;
        let ack = self
            .await_message(ANSWER_WAIT, |m| match m {
                UbxMessage::Ack(a) if (a.class, a.id) == (0x06, 0x8a) => Some(a.accepted),
                _ => None,
            })
            .await?;
        match ack {
            Some(true) => {}
            Some(false) => {
                return Err(refusal(
                    "the receiver refused CFG-VALSET (ACK-NAK): a key it does not know, or a \
                     layer it cannot write; nothing was changed",
                    format!(
                        "with --flash, try without it (a receiver without flash refuses that \
                         layer); else check gnss.ublox_port ({}) against the port this cable \
                         reaches",
                        port_name(port)
                    ),
                ));
            }
            None => {
                return Err(refusal(
                    format!(
                        "no answer to CFG-VALSET in {:.0} s",
                        ANSWER_WAIT.as_secs_f64()
                    ),
                    "the receiver answered MON-VER on this port but did not acknowledge the \
                     change (a busy output can crowd out the ACK): run check --configure again",
                ));
            }
        }
        let keys: Vec<u32> = items.iter().map(|i| i.key).collect();
        self.send(&config::valget_poll(&keys).map_err(|e| refusal(e.to_string(), ""))?)
            .await?;
        let answer = self
            .await_message(ANSWER_WAIT, |m| match m {
                UbxMessage::CfgValGet(a) => Some(a),
                _ => None,
            })
            .await?
            .ok_or_else(|| refusal("no answer to CFG-VALGET", "try again; check the cable"))?;
        let differ: Vec<String> = wanted
            .iter()
            .filter(|w| {
                !answer
                    .items
                    .iter()
                    .any(|i| i.key == w.item.key && i.value == w.item.value)
            })
            .map(|w| format!("{} ({:#010x})", w.name, w.item.key))
            .collect();
        if differ.is_empty() {
            Ok(wanted)
        } else {
            Err(refusal(
                format!(
                    "the receiver acknowledged but reads back other values for {}",
                    differ.join(", ")
                ),
                "a newer receiver may lock these keys; set them with u-center and run check \
                 again",
            ))
        }
    }

    async fn send(&mut self, frame: &[u8]) -> Result<(), Refusal> {
        self.io
            .write_all(frame)
            .await
            .map_err(|e| refusal(format!("writing to the receiver: {e}"), "check the cable"))?;
        self.io
            .flush()
            .await
            .map_err(|e| refusal(format!("writing to the receiver: {e}"), "check the cable"))
    }

    /// Reads until `pick` takes a message or `wait` passes.
    async fn await_message<T>(
        &mut self,
        wait: Duration,
        mut pick: impl FnMut(UbxMessage) -> Option<T>,
    ) -> Result<Option<T>, Refusal> {
        let end = Instant::now() + wait;
        loop {
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            let n = match tokio::time::timeout(left, self.io.read(&mut self.buf)).await {
                Err(_) | Ok(Ok(0)) => return Ok(None),
                Ok(Ok(n)) => n,
                Ok(Err(e)) => {
                    return Err(refusal(
                        format!("reading the receiver: {e}"),
                        "check the cable",
                    ));
                }
            };
            let mut found = None;
            let chunk = self.buf.get(..n).unwrap_or_default();
            self.framer.push_frames(chunk, |frame| {
                if found.is_none()
                    && let Frame::Ubx(f) = frame
                    && let Ok(Some(message)) = ubx::decode(&f)
                {
                    found = pick(message);
                }
            });
            if found.is_some() {
                return Ok(found);
            }
        }
    }
}

/// The port's name as the configuration writes it.
pub fn port_name(port: Port) -> &'static str {
    match port {
        Port::Uart1 => "uart1",
        Port::Uart2 => "uart2",
        Port::Usb => "usb",
    }
}
