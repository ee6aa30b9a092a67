//! Where the processes' log lines go: the systemd journal when the process runs under
//! systemd with its stderr connected to the journal, a terminal otherwise.
//!
//! Under systemd (`JOURNAL_STREAM` names the process's own stderr, as systemd sets it for
//! `StandardError=journal`) events go to journald's native socket through
//! `tracing-journald`: one journal entry per event with its priority (error 3, warn 4,
//! info 5, debug 6, trace 7), `SYSLOG_IDENTIFIER` and the event's fields, no colour codes.
//! If the journal socket cannot be reached the events go to stderr, which journald
//! captures, without colours. Outside systemd: stderr, coloured only when it is a
//! terminal. The filter is `RUST_LOG` (tracing's env-filter syntax), default `info`.
//! Logging is never done on a real-time hot path, so the choice does not affect timing.
//!
//! A short-lived process (the driver's `safe-stop`, run by `ExecStopPost=`) logs through
//! its stderr stream instead ([`init_stream`]): journald attributes a native-protocol
//! datagram to a unit by reading the sender's cgroup from `/proc` when it processes the
//! datagram, which fails once the sender has exited, so a process that logs and exits at
//! once may have its lines missing from `journalctl -u <unit>` (the boot test's missing
//! second "safe-stop: NMT stop written"). A stream's lines are attributed
//! by the stream, which systemd opened for the unit. Each line carries its priority as a
//! `<N>` prefix, which journald reads (`SyslogLevelPrefix=`, on by default).

use std::io::IsTerminal;
use std::os::unix::fs::MetadataExt;

use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// Environment variable systemd sets to `<device>:<inode>` of the journal stream it
/// connected to stdout/stderr.
pub const ENV_JOURNAL_STREAM: &str = "JOURNAL_STREAM";

/// Where log events go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogSink {
    /// journald's native protocol (structured, with priorities).
    Journal,
    /// stderr; `ansi` when it is a terminal.
    Stderr {
        /// Colour codes on.
        ansi: bool,
    },
}

impl std::fmt::Display for LogSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LogSink::Journal => f.write_str("the systemd journal"),
            LogSink::Stderr { ansi: true } => f.write_str("stderr (terminal)"),
            LogSink::Stderr { ansi: false } => f.write_str("stderr (no colours)"),
        }
    }
}

/// True when `journal_stream` (`JOURNAL_STREAM`'s value, `<device>:<inode>` in decimal)
/// names the file with device `dev` and inode `ino`: that file is a stream into the journal.
pub fn names_journal_stream(journal_stream: &str, dev: u64, ino: u64) -> bool {
    let Some((d, i)) = journal_stream.trim().split_once(':') else {
        return false;
    };
    matches!((d.parse::<u64>(), i.parse::<u64>()), (Ok(d), Ok(i)) if d == dev && i == ino)
}

/// True when this process's stderr is connected to the journal (systemd's recommended
/// check: `JOURNAL_STREAM` equals stderr's device and inode).
pub fn stderr_is_journal() -> bool {
    let Some(value) = std::env::var_os(ENV_JOURNAL_STREAM) else {
        return false;
    };
    let Ok(meta) = std::fs::metadata("/proc/self/fd/2") else {
        return false;
    };
    names_journal_stream(&value.to_string_lossy(), meta.dev(), meta.ino())
}

/// The sink for this process: [`LogSink::Journal`] when stderr goes to the journal,
/// else stderr (coloured if a terminal).
pub fn choose_sink() -> LogSink {
    if stderr_is_journal() {
        LogSink::Journal
    } else {
        LogSink::Stderr {
            ansi: std::io::stderr().is_terminal(),
        }
    }
}

/// Installs the global `tracing` subscriber for a process called `identifier` (the
/// journal's `SYSLOG_IDENTIFIER`) and returns where events go. Call once, first thing in
/// `main`; a second call leaves the first subscriber in place.
pub fn init(identifier: &str) -> LogSink {
    let filter = || EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let mut sink = choose_sink();
    if sink == LogSink::Journal {
        match tracing_journald::layer() {
            Ok(layer) => {
                let layer = layer.with_syslog_identifier(identifier.to_owned());
                let _ = tracing_subscriber::registry()
                    .with(filter())
                    .with(layer)
                    .try_init();
                return sink;
            }
            // The journal socket is unreachable: stderr still reaches journald.
            Err(_) => sink = LogSink::Stderr { ansi: false },
        }
    }
    let ansi = matches!(sink, LogSink::Stderr { ansi: true });
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .with_env_filter(filter())
        .try_init();
    sink
}

/// The syslog priority of a level (error 3, warn 4, info 5, debug 6, trace 7), as
/// `tracing-journald` maps them.
pub fn syslog_priority(level: &tracing::Level) -> u8 {
    match *level {
        tracing::Level::ERROR => 3,
        tracing::Level::WARN => 4,
        tracing::Level::INFO => 5,
        tracing::Level::DEBUG => 6,
        tracing::Level::TRACE => 7,
    }
}

/// Lines prefixed with `<priority>` for journald's stream parser, without time or colours.
struct PriorityPrefixed;

impl<S, N> tracing_subscriber::fmt::FormatEvent<S, N> for PriorityPrefixed
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut writer: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        write!(writer, "<{}>", syslog_priority(event.metadata().level()))?;
        tracing_subscriber::fmt::format()
            .without_time()
            .with_level(false)
            .with_ansi(false)
            .format_event(ctx, writer, event)
    }
}

/// Installs the subscriber of a short-lived process (see the module documentation): under
/// systemd, stderr lines with `<priority>` prefixes (attributed to the unit by its stream);
/// otherwise as [`init`]'s stderr. The filter is `RUST_LOG`, default `info`.
pub fn init_stream() -> LogSink {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    if stderr_is_journal() {
        let _ = tracing_subscriber::fmt()
            .with_writer(std::io::stderr)
            .with_env_filter(filter)
            .event_format(PriorityPrefixed)
            .try_init();
        return LogSink::Stderr { ansi: false };
    }
    let ansi = std::io::stderr().is_terminal();
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .with_env_filter(filter)
        .try_init();
    LogSink::Stderr { ansi }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn journal_stream_must_name_the_same_device_and_inode() {
        assert!(names_journal_stream("8:12345", 8, 12345));
        assert!(names_journal_stream("8:12345\n", 8, 12345));
        assert!(!names_journal_stream("8:12346", 8, 12345));
        assert!(!names_journal_stream("9:12345", 8, 12345));
        for bad in ["", "8", "8:", ":1", "a:b", "8:12345:1"] {
            assert!(!names_journal_stream(bad, 8, 12345), "{bad:?}");
        }
    }

    /// Our own stderr's device and inode in `JOURNAL_STREAM` form are recognised, which
    /// is what systemd puts there for a journal-connected stderr.
    #[test]
    fn stderr_identity_matches_its_own_device_and_inode() {
        let meta = std::fs::metadata("/proc/self/fd/2").unwrap();
        let value = format!("{}:{}", meta.dev(), meta.ino());
        assert!(names_journal_stream(&value, meta.dev(), meta.ino()));
    }
}
