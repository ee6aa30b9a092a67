//! pyScienceMode as an independent peer of our ScienceMode 2 codec (`fes-sciencemode`): two
//! implementations that share no code must agree on every byte.
//!
//! The test installs pyScienceMode (pinned, [`PYSCIENCEMODE`]) from PyPI into a virtual
//! environment under `target/tmp`, kept between runs, and runs
//! `tests/python/sciencemode_peer.py`, which only calls pyScienceMode's own code:
//!
//! * device packets our encoder produced are split by pyScienceMode's serial reader and read
//!   by its acknowledgement parsers: same packet numbers, commands, data and meanings, and its
//!   packet builder rebuilds the very bytes from the fields it read;
//! * host commands our encoder produced are rebuilt by its packet builder from the same
//!   fields: the same bytes;
//! * the packets its `Rehastim2` client builds for a session are decoded by ours to the
//!   fields the client was given.
//!
//! Without python3, its venv module, pip or a route to PyPI the test fails and says which;
//! it never skips.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

use fes_sciencemode::{
    AckResult, ChannelListInit, ChannelListUpdate, ChannelPulse, Decoder, MAX_PACKET_LEN, Message,
    Packet, PulseMode, SinglePulse, StimulationError, StimulationMode,
};

/// The pyScienceMode release the peer tests run against.
pub const PYSCIENCEMODE: &str = "pyScienceMode==1.1.5";
const PYSCIENCEMODE_VERSION: &str = "1.1.5";

fn run(cmd: &mut Command, what: &str, hint: &str) -> String {
    let out = cmd
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}. {hint}"));
    assert!(
        out.status.success(),
        "{what} failed ({}). {hint}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn has_pinned_pysciencemode(python: &Path) -> bool {
    python.is_file()
        && Command::new(python)
            .args([
                "-c",
                &format!(
                    "import importlib.metadata as m, pysciencemode; \
                     assert m.version('pysciencemode') == '{PYSCIENCEMODE_VERSION}'"
                ),
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
}

/// The Python interpreter of a virtual environment holding [`PYSCIENCEMODE`], created on
/// first use (pip from PyPI) and kept under `target/tmp` for later runs.
pub fn peer_python() -> PathBuf {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("pysciencemode-{PYSCIENCEMODE_VERSION}-venv"));
            let python = dir.join("bin/python");
            if has_pinned_pysciencemode(&python) {
                return python;
            }
            // Built beside, then moved into place: a run killed half-way leaves no venv that
            // looks finished. (`python -m pip` works from the moved venv; its scripts would not.)
            let building = dir.with_file_name(format!(
                "pysciencemode-{PYSCIENCEMODE_VERSION}-venv.building-{}",
                std::process::id()
            ));
            let _ = std::fs::remove_dir_all(&building);
            // A failed build leaves nothing behind.
            struct Remove<'a>(&'a Path);
            impl Drop for Remove<'_> {
                fn drop(&mut self) {
                    let _ = std::fs::remove_dir_all(self.0);
                }
            }
            let _cleanup = Remove(&building);
            run(
                Command::new("python3").args(["-m", "venv"]).arg(&building),
                "creating a Python virtual environment (python3 -m venv)",
                "Install python3 and python3-venv (scripts/setup does).",
            );
            run(
                Command::new(building.join("bin/python")).args([
                    "-m",
                    "pip",
                    "install",
                    "--disable-pip-version-check",
                    "--no-input",
                    "--quiet",
                    PYSCIENCEMODE,
                ]),
                &format!("pip install {PYSCIENCEMODE}"),
                "The ScienceMode peer test needs pip and a route to PyPI (or a pip index / \
                 find-links that holds pyScienceMode and its dependencies).",
            );
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::rename(&building, &dir).unwrap_or_else(|e| {
                panic!("moving {} to {}: {e}", building.display(), dir.display())
            });
            assert!(
                has_pinned_pysciencemode(&python),
                "{PYSCIENCEMODE} installed into {} but does not import",
                dir.display()
            );
            python
        })
        .clone()
}

/// `tests/python/<name>`.
pub fn python_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python")
        .join(name)
}

/// Runs the peer script in `mode` with `input` on stdin; its stdout lines.
fn peer(mode: &str, input: &str) -> Vec<String> {
    let mut child = Command::new(peer_python())
        .arg(python_script("sciencemode_peer.py"))
        .arg(mode)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the pyScienceMode peer script");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "sciencemode_peer.py {mode}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_owned)
        .collect()
}

fn encode(p: &Packet) -> Vec<u8> {
    let mut buf = [0u8; MAX_PACKET_LEN];
    let n = p.encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

/// The command data (unstuffed) of a packet, as our codec lays it out.
fn command_data(p: &Packet) -> Vec<u8> {
    let (data, len) = p.data();
    data[2..len].to_vec()
}

#[test]
fn pysciencemode_reads_our_device_packets() {
    // Every device → host packet the controller acts on, with the meaning pyScienceMode's
    // ack parsers must give it (None: pyScienceMode has no parser for that command).
    let ack = |n, message| Packet::new(n, message);
    let cases: Vec<(Packet, Option<&str>)> = vec![
        (ack(0, Message::Init { version: 1 }), None),
        (
            ack(
                1,
                Message::GetStimulationModeAck {
                    result: AckResult::Ok,
                    mode: Some(StimulationMode::Started),
                },
            ),
            Some("Stimulation started"),
        ),
        (
            ack(
                2,
                Message::GetStimulationModeAck {
                    result: AckResult::Ok,
                    mode: Some(StimulationMode::Start),
                },
            ),
            Some("Start Mode"),
        ),
        (
            ack(
                3,
                Message::InitChannelListModeAck {
                    result: AckResult::Ok,
                },
            ),
            Some("Stimulation initialized"),
        ),
        (
            ack(
                4,
                Message::InitChannelListModeAck {
                    result: AckResult::ParameterError,
                },
            ),
            Some("Parameter error"),
        ),
        (
            ack(
                5,
                Message::StartChannelListModeAck {
                    result: AckResult::Ok,
                },
            ),
            Some("Stimulation started"),
        ),
        (
            ack(
                6,
                Message::StartChannelListModeAck {
                    result: AckResult::WrongModeError,
                },
            ),
            Some("Wrong mode error"),
        ),
        (
            ack(
                7,
                Message::StopChannelListModeAck {
                    result: AckResult::Ok,
                },
            ),
            Some("Stimulation stopped"),
        ),
        (
            ack(
                8,
                Message::StopChannelListModeAck {
                    result: AckResult::BusyError,
                },
            ),
            Some("Busy error"),
        ),
        (
            ack(
                9,
                Message::StartChannelListModeAck {
                    result: AckResult::TransferError,
                },
            ),
            Some("Transfer error"),
        ),
        (
            ack(
                11,
                Message::SinglePulseAck {
                    result: AckResult::Ok,
                },
            ),
            None,
        ),
        (
            ack(
                12,
                Message::StimulationError {
                    error: StimulationError::Electrode,
                },
            ),
            Some("Electrode error"),
        ),
        (
            ack(
                13,
                Message::StimulationError {
                    error: StimulationError::EmergencySwitch,
                },
            ),
            Some("Emergency switch activated/not connected"),
        ),
        (
            ack(
                14,
                Message::StimulationError {
                    error: StimulationError::StimulationModule,
                },
            ),
            Some("Stimulation module error"),
        ),
    ];
    let stream: Vec<u8> = cases.iter().flat_map(|(p, _)| encode(p)).collect();
    let lines = peer("parse", &hex(&stream));
    assert_eq!(
        lines.len(),
        cases.len(),
        "pyScienceMode split our stream into {} packets: {lines:#?}",
        lines.len()
    );
    for ((packet, meaning), line) in cases.iter().zip(&lines) {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let ours = encode(packet);
        assert_eq!(v["number"], u64::from(packet.number), "{packet:?}: {line}");
        assert_eq!(
            v["command"],
            format!("{:?}", packet.message.command()),
            "{packet:?}: {line}"
        );
        let data: Vec<u8> = serde_json::from_value(v["data"].clone()).unwrap();
        assert_eq!(data, command_data(packet), "{packet:?}: {line}");
        assert_eq!(
            v["ack"].as_str().map(str::trim),
            *meaning,
            "{packet:?}: {line}"
        );
        assert_eq!(v["bytes"], hex(&ours), "{packet:?}: {line}");
        assert_eq!(
            v["rebuilt"],
            hex(&ours),
            "pyScienceMode rebuilds {packet:?} differently: {line}"
        );
    }
}

#[test]
fn pysciencemode_builds_our_host_commands_byte_for_byte() {
    let list = ChannelListUpdate::new(&[
        ChannelPulse {
            mode: PulseMode::Single,
            pulse_width_us: 0x010A, // 266 us: LSB 0x0A is stuffed
            current_ma: 0x0F,       // 15 mA: stuffed
        },
        ChannelPulse {
            mode: PulseMode::Triplet,
            pulse_width_us: 500,
            current_ma: 0x55, // 85 mA: stuffed
        },
        ChannelPulse {
            mode: PulseMode::Doublet,
            pulse_width_us: 20,
            current_ma: 126,
        },
    ])
    .unwrap();
    let commands = [
        Packet::new(
            3,
            Message::InitAck {
                result: AckResult::Ok,
            },
        ),
        Packet::new(
            4,
            Message::InitAck {
                result: AckResult::VersionError,
            },
        ),
        Packet::new(0, Message::Watchdog),
        Packet::new(
            5,
            Message::InitChannelListMode(ChannelListInit {
                low_frequency_factor: 7,
                active_channels: 0b1000_0101,
                low_frequency_channels: 0b1000_0000,
                inter_pulse_interval_code: 0x0A,
                main_interval_code: 0x0181,
                channel_execution: 0,
            }),
        ),
        Packet::new(6, Message::StartChannelListMode(list)),
        Packet::new(7, Message::StopChannelListMode),
        Packet::new(
            8,
            Message::SinglePulse(SinglePulse {
                channel: 7,
                pulse_width_us: 0x01F0, // LSB 0xF0, the start byte: stuffed
                current_ma: 0x0A,
            }),
        ),
        Packet::new(
            255,
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 200,
                current_ma: 20,
            }),
        ),
    ];
    let input: String = commands
        .iter()
        .map(|p| {
            format!(
                "{}\n",
                serde_json::json!({
                    "number": p.number,
                    "command": format!("{:?}", p.message.command()),
                    "data": command_data(p),
                })
            )
        })
        .collect();
    let lines = peer("rebuild", &input);
    assert_eq!(lines.len(), commands.len());
    let mut differing = 0;
    for (p, line) in commands.iter().zip(&lines) {
        // pyScienceMode also escapes 0x55 and 0x0A, which the protocol description sends
        // as they are (§2.2: every Table 6 constant "except the stuffing key" is escaped;
        // docs/sciencemode.md): where the packet data holds one, the bytes differ in
        // exactly that, and our decoder reads pyScienceMode's bytes to the same packet.
        // Elsewhere the bytes are the same.
        let (data, len) = p.data();
        if data[..len].iter().any(|b| matches!(b, 0x55 | 0x0A)) {
            differing += 1;
            let theirs = unhex(line);
            let out: Vec<_> = Decoder::new().feed(&theirs).collect();
            assert_eq!(out, [Ok(*p)], "{p:?}: {line}");
        } else {
            assert_eq!(*line, hex(&encode(p)), "{p:?}");
        }
    }
    // The cases cover both forms.
    assert!(differing > 0 && differing < commands.len());
}

#[test]
fn we_read_the_packets_of_pysciencemodes_client() {
    let lines = peer("client", "");
    let mut decoded = std::collections::BTreeMap::new();
    for line in &lines {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let bytes = unhex(v["bytes"].as_str().unwrap());
        let out: Vec<_> = Decoder::new().feed(&bytes).collect();
        let [Ok(packet)] = out[..] else {
            panic!("{line}: decoded to {out:?}");
        };
        // And our encoder produces the very bytes.
        assert_eq!(encode(&packet), bytes, "{line}");
        decoded.insert(v["what"].as_str().unwrap().to_owned(), packet);
    }
    assert_eq!(
        decoded["init_ack"],
        Packet::new(
            3,
            Message::InitAck {
                result: AckResult::Ok
            }
        )
    );
    // Channels 1 and 3 (channel 3 at the low frequency), 25 ms main interval, 3 ms
    // inter-pulse interval, low-frequency factor 2.
    let Message::InitChannelListMode(init) = decoded["init_channel_list"].message else {
        panic!("{:?}", decoded["init_channel_list"]);
    };
    assert_eq!(decoded["init_channel_list"].number, 7);
    assert_eq!(
        init,
        ChannelListInit {
            low_frequency_factor: 2,
            active_channels: 0b101,
            low_frequency_channels: 0b100,
            inter_pulse_interval_code: 3,
            main_interval_code: 48,
            channel_execution: 0,
        }
    );
    assert_eq!(init.main_interval_us(), 25_000);
    assert_eq!(init.inter_pulse_interval_us(), 3_000);
    let entries = |what: &str| match decoded[what].message {
        Message::StartChannelListMode(list) => list.entries().to_vec(),
        other => panic!("{what}: {other:?}"),
    };
    assert_eq!(decoded["start_channel_list"].number, 8);
    assert_eq!(
        entries("start_channel_list"),
        [
            ChannelPulse {
                mode: PulseMode::Single,
                pulse_width_us: 200,
                current_ma: 20
            },
            ChannelPulse {
                mode: PulseMode::Doublet,
                pulse_width_us: 300,
                current_ma: 32
            },
        ]
    );
    // pause_stimulation: the same list at 0 mA.
    assert_eq!(decoded["pause"].number, 9);
    assert!(
        entries("pause").iter().all(|e| e.current_ma == 0),
        "{:?}",
        entries("pause")
    );
    assert_eq!(decoded["watchdog"], Packet::new(11, Message::Watchdog));
    assert_eq!(
        decoded["stop"],
        Packet::new(12, Message::StopChannelListMode)
    );
}
