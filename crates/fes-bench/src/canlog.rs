//! `can.log`: every frame of a bench run in `candump -L` format ([`fes_can::candump`]),
//! whatever the bus: on the host bus from its tap station (the frames every other station
//! sent, with the kernel's receive time), on a SocketCAN interface from can-utils'
//! `candump -L`. `cantools decode crates/fes-can/dbc/fes.dbc < can.log` and python-can's
//! `can.LogReader` read it (docs/bench.md).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use fes_hostbus::{HostBus, Station};

/// The interface name written for the host bus (a `candump` channel is one word).
pub const HOSTBUS_CHANNEL: &str = "hostbus0";

/// Why the log could not be written.
#[derive(Debug, thiserror::Error)]
pub enum CanLogError {
    /// The log file or the tap could not be opened, or a write failed.
    #[error("can.log {}: cannot {op}: {source}", path.display())]
    Io {
        /// What was being done.
        op: &'static str,
        /// The file (or the bus directory).
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// `candump` (can-utils) could not be started.
    #[error("cannot start `candump -L {iface}` (install can-utils: scripts/setup): {source}")]
    Candump {
        /// The interface.
        iface: String,
        /// The reason.
        source: std::io::Error,
    },
}

enum Source {
    Tap {
        stop: Arc<AtomicBool>,
        thread: JoinHandle<Result<(), CanLogError>>,
    },
    Candump(Child),
}

/// A running `can.log` writer; [`CanLog::finish`] ends it.
pub struct CanLog {
    path: PathBuf,
    frames: Arc<AtomicU64>,
    source: Source,
}

fn io<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> CanLogError + 'a {
    move |source| CanLogError::Io {
        op,
        path: path.to_path_buf(),
        source,
    }
}

impl CanLog {
    /// Starts logging the bus `iface` (`hostbus:<dir>` or a SocketCAN interface) into
    /// `path`. On the host bus it takes the tap station, which a test's injector then
    /// cannot have.
    pub fn start(iface: &str, path: &Path) -> Result<Self, CanLogError> {
        let frames = Arc::new(AtomicU64::new(0));
        let source = match fes_hostbus::bus_dir(iface) {
            Some(dir) => {
                let tap = HostBus::open(dir, Station::Tap, Some(Duration::from_millis(20)))
                    .map_err(io("open the host bus's tap", dir))?;
                let file = File::create(path).map_err(io("create", path))?;
                let stop = Arc::new(AtomicBool::new(false));
                let (s, n, p) = (stop.clone(), frames.clone(), path.to_path_buf());
                let thread = std::thread::Builder::new()
                    .name("can.log".into())
                    .spawn(move || write_tap(&tap, BufWriter::new(file), &s, &n, &p))
                    .map_err(io("start the writer thread", path))?;
                Source::Tap { stop, thread }
            }
            None => {
                let file = File::create(path).map_err(io("create", path))?;
                let child = Command::new("candump")
                    .args(["-L", iface])
                    .stdout(file)
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(|source| CanLogError::Candump {
                        iface: iface.to_owned(),
                        source,
                    })?;
                Source::Candump(child)
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            frames,
            source,
        })
    }

    /// Stops logging; the file is complete and flushed. Returns the frames written (for
    /// `candump`, the lines of the file).
    pub fn finish(self) -> Result<u64, CanLogError> {
        match self.source {
            Source::Tap { stop, thread } => {
                stop.store(true, Ordering::Relaxed);
                match thread.join() {
                    Ok(r) => r?,
                    Err(_) => {
                        return Err(CanLogError::Io {
                            op: "finish (the writer thread panicked)",
                            path: self.path,
                            source: std::io::Error::other("panic"),
                        });
                    }
                }
                Ok(self.frames.load(Ordering::Relaxed))
            }
            Source::Candump(mut child) => {
                // SIGINT: candump flushes its output and exits.
                // SAFETY: kill(2) on our own child's pid, not yet reaped.
                unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
                let _ = child.wait();
                let text = std::fs::read_to_string(&self.path).map_err(io("read", &self.path))?;
                Ok(text.lines().count() as u64)
            }
        }
    }
}

/// The tap's loop: every frame as a `candump -L` line until `stop`.
fn write_tap(
    tap: &HostBus,
    mut out: BufWriter<File>,
    stop: &AtomicBool,
    frames: &AtomicU64,
    path: &Path,
) -> Result<(), CanLogError> {
    let mut line = String::with_capacity(64);
    while !stop.load(Ordering::Relaxed) {
        let Some(r) = tap.recv().map_err(io("read the tap", path))? else {
            continue;
        };
        let t = r.rx_realtime_ns.unwrap_or_else(|| {
            SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64)
        });
        line.clear();
        let f = &r.frame;
        fes_can::candump::log_line(
            &mut line,
            t,
            HOSTBUS_CHANNEL,
            f.can_id,
            &f.data[..usize::from(f.len.min(8))],
        );
        line.push('\n');
        out.write_all(line.as_bytes()).map_err(io("write", path))?;
        frames.fetch_add(1, Ordering::Relaxed);
    }
    out.flush().map_err(io("flush", path))
}
