//! Child processes whose output is streamed line by line, with a deadline and a clean
//! kill of the whole process group.

use std::io::{BufRead, BufReader, Read};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::thread::JoinHandle;
use std::time::Instant;

/// A running child with its merged stdout/stderr as a stream of lines.
pub(crate) struct Streamed {
    child: Child,
    lines: Receiver<String>,
    readers: Vec<JoinHandle<()>>,
    reaped: Option<ExitStatus>,
}

/// The outcome of waiting for the next line.
pub(crate) enum Next {
    /// A line (without its end of line; `\r` removed; invalid UTF-8 replaced).
    Line(String),
    /// Both output streams are closed.
    Eof,
    /// The deadline passed first.
    TimedOut,
}

fn forward<R: Read + Send + 'static>(r: R, tx: std::sync::mpsc::Sender<String>) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let mut r = BufReader::new(r);
        let mut buf = Vec::new();
        loop {
            buf.clear();
            match r.read_until(b'\n', &mut buf) {
                Ok(0) | Err(_) => break,
                Ok(_) => {
                    let line = String::from_utf8_lossy(&buf).replace(['\r', '\n'], "");
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            }
        }
    })
}

impl Streamed {
    /// Spawns `cmd` in its own process group (so it can be killed with all its
    /// children), stdin from /dev/null, stdout and stderr captured; the child is killed
    /// if the spawning thread dies.
    pub(crate) fn spawn(cmd: &mut Command) -> std::io::Result<Self> {
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0);
        crate::child::dies_with_parent(cmd);
        let mut child = cmd.spawn()?;
        let (tx, rx) = channel();
        let mut readers = Vec::new();
        if let Some(out) = child.stdout.take() {
            readers.push(forward(out, tx.clone()));
        }
        if let Some(err) = child.stderr.take() {
            readers.push(forward(err, tx));
        }
        Ok(Self {
            child,
            lines: rx,
            readers,
            reaped: None,
        })
    }

    /// Waits for the next output line until `deadline`.
    pub(crate) fn next_line(&self, deadline: Instant) -> Next {
        let timeout = deadline.saturating_duration_since(Instant::now());
        match self.lines.recv_timeout(timeout) {
            Ok(line) => Next::Line(line),
            Err(RecvTimeoutError::Timeout) => Next::TimedOut,
            Err(RecvTimeoutError::Disconnected) => Next::Eof,
        }
    }

    /// Kills the child's whole process group (SIGKILL).
    pub(crate) fn kill_group(&mut self) {
        if self.reaped.is_some() {
            return;
        }
        if let Ok(pgid) = i32::try_from(self.child.id()) {
            // SAFETY: kill(2) with a negative pid signals the process group we created
            // for this child (process_group(0) made the child its leader).
            unsafe {
                libc::kill(-pgid, libc::SIGKILL);
            }
        }
    }

    /// Waits up to `deadline` for the child to exit; `None` if it is still running.
    pub(crate) fn wait_until(&mut self, deadline: Instant) -> std::io::Result<Option<ExitStatus>> {
        loop {
            if let Some(s) = self.reaped {
                return Ok(Some(s));
            }
            if let Some(s) = self.child.try_wait()? {
                self.reaped = Some(s);
                for r in self.readers.drain(..) {
                    let _ = r.join();
                }
                return Ok(Some(s));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    /// Lines still buffered after the child exited.
    pub(crate) fn remaining_lines(&self) -> Vec<String> {
        self.lines.try_iter().collect()
    }
}

impl Drop for Streamed {
    fn drop(&mut self) {
        if self.reaped.is_none() {
            self.kill_group();
            let _ = self.child.wait();
        }
    }
}

/// The shell-style exit code of a status: the code, or 128 + the signal number.
pub(crate) fn exit_code(status: ExitStatus) -> i32 {
    status
        .code()
        .unwrap_or_else(|| 128 + status.signal().unwrap_or(0))
}
