//! The prescription file (`format = "fes-prescription/1"`, TOML): the dose ceilings of one
//! patient's stimulation, kept apart from the device configuration.
//!
//! It is owned by root and read-only to the services (scripts/install: root:root 0644,
//! `/etc/fes/prescription.toml`). stim-driver refuses to start when its interlocks or the
//! stimulator limits it would send in CONFIG exceed it, rt-core refuses to start when its
//! pulse exceeds it, and the supervisor writes its SHA-256 into every recording, so a run
//! always names the prescription it ran under.
//!
//! ```toml
//! format = "fes-prescription/1"
//! label = "bench: fast muscle"      # optional free text (no patient data)
//! max_amplitude_ua = 20000          # current of each phase, uA (1..=150000)
//! max_phase_width_us = 200          # width of each phase, us (1..=1000)
//! max_charge_per_phase_nc = 4000    # amplitude x phase width, nC (<= the product of the two)
//! min_ipi_us = 2000                 # shortest interval between pulses, us (1000..=1000000)
//! max_pulses_per_s = 100            # most pulses in any 1 s (<= 1e6 / min_ipi_us)
//! electrode_area_cm2 = 25.0         # optional: the smallest electrode's area
//! current_density_acknowledged = false  # must be true to allow > 2 mA/cm2 r.m.s.
//! ```
//!
//! One pulse is charge-balanced and biphasic (docs/can-protocol.md, "What one PULSE is"):
//! amplitude and width are those of each phase, and the charge is the charge per phase.
//! With an electrode area, the r.m.s. current density at the prescription's ceilings,
//! `I * sqrt(2 * w * f) / A` (two phases per pulse, `f` = `max_pulses_per_s`), must not exceed
//! IEC 60601-2-10's 2 mA/cm² attention level unless `current_density_acknowledged` says the
//! prescriber has considered it.

mod sha256;

use std::path::{Path, PathBuf};

use serde::Deserialize;

pub use sha256::{sha256, sha256_hex};

/// The format tag this version reads.
pub const FORMAT: &str = "fes-prescription/1";
/// Where the services look for it unless configured otherwise.
pub const DEFAULT_PATH: &str = "/etc/fes/prescription.toml";
/// IEC 60601-2-10's attention level for the r.m.s. current density under an electrode,
/// mA/cm².
pub const CURRENT_DENSITY_ATTENTION_MA_PER_CM2: f64 = 2.0;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    format: String,
    #[serde(default)]
    label: Option<String>,
    max_amplitude_ua: u32,
    max_phase_width_us: u32,
    max_charge_per_phase_nc: u32,
    min_ipi_us: u32,
    max_pulses_per_s: u32,
    #[serde(default)]
    electrode_area_cm2: Option<f64>,
    #[serde(default)]
    current_density_acknowledged: bool,
}

/// A validated prescription and the checksum of the file it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Prescription {
    /// Free text naming it (no patient data).
    pub label: Option<String>,
    /// Current of each phase, uA.
    pub max_amplitude_ua: u32,
    /// Width of each phase, us.
    pub max_phase_width_us: u32,
    /// Charge per phase (amplitude x width), nC.
    pub max_charge_per_phase_nc: u32,
    /// Shortest interval between two pulses, us.
    pub min_ipi_us: u32,
    /// Most pulses in any 1 s.
    pub max_pulses_per_s: u32,
    /// The smallest electrode's area, cm², if stated.
    pub electrode_area_cm2: Option<f64>,
    /// The prescriber allows an r.m.s. current density above 2 mA/cm².
    pub current_density_acknowledged: bool,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
    /// The file it was read from (None: parsed from text).
    pub path: Option<PathBuf>,
}

/// A prescription that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PrescriptionError {
    /// The file cannot be read.
    #[error("prescription {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not UTF-8 text.
    #[error("prescription{at}: {source}")]
    Utf8 {
        /// `" <path>"` or `""`.
        at: String,
        /// The decoding error.
        #[source]
        source: std::str::Utf8Error,
    },
    /// Not TOML of this format.
    #[error("prescription{at}: {source}")]
    Parse {
        /// `" <path>"` or `""`.
        at: String,
        /// The parser's error.
        #[source]
        source: toml::de::Error,
    },
    /// Another `format`.
    #[error("prescription{at}: format = {found:?}, this version reads {FORMAT:?}")]
    Format {
        /// `" <path>"` or `""`.
        at: String,
        /// What the file says.
        found: String,
    },
    /// A value outside its range or inconsistent with another.
    #[error("prescription{at}: {field} = {value}: {why}")]
    Invalid {
        /// `" <path>"` or `""`.
        at: String,
        /// The key.
        field: &'static str,
        /// Its value.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// The file could be changed by someone other than root or this process's user.
    #[error(
        "prescription {path}: {why}; a prescription must be owned by root or by the \
         user the process runs as (uid {euid}) and writable by its owner only \
         (e.g. root:root 0644)"
    )]
    Untrusted {
        /// The file.
        path: PathBuf,
        /// What allows the change.
        why: String,
        /// The process's effective user.
        euid: u32,
    },
}

/// Why the prescription at `path` (its metadata `file`, its directory's `dir`) could be
/// changed by someone other than root or user `euid`, if it could: the file owned by
/// another user, or writable by its group or others, or its directory writable by others
/// without the sticky bit (anyone could replace the file).
fn untrusted(
    file: &std::fs::Metadata,
    dir: Option<&std::fs::Metadata>,
    euid: u32,
) -> Option<String> {
    use std::os::unix::fs::MetadataExt as _;
    let owner = file.uid();
    if owner != 0 && owner != euid {
        return Some(format!("owned by uid {owner}"));
    }
    let mode = file.mode() & 0o7777;
    if mode & 0o022 != 0 {
        return Some(format!("mode {mode:04o} lets its group or others write it"));
    }
    if let Some(d) = dir {
        let dmode = d.mode() & 0o7777;
        let downer = d.uid();
        if downer != 0 && downer != euid {
            return Some(format!("its directory is owned by uid {downer}"));
        }
        if dmode & 0o022 != 0 && dmode & 0o1000 == 0 {
            return Some(format!(
                "its directory (mode {dmode:04o}) lets its group or others replace it"
            ));
        }
    }
    None
}

/// The first 6 bytes of a SHA-256 given in hex ([`Prescription::fingerprint`]); zeros
/// where the text is not hex.
pub fn fingerprint_of(sha256_hex: &str) -> [u8; 6] {
    let mut out = [0u8; 6];
    for (i, b) in out.iter_mut().enumerate() {
        *b = sha256_hex
            .get(2 * i..2 * i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0);
    }
    out
}

/// A fingerprint as 12 hex digits.
pub fn fingerprint_hex(f: &[u8; 6]) -> String {
    f.iter().map(|b| format!("{b:02x}")).collect()
}

/// A limit of some layer above the prescription.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{layer} {field} = {value} {unit} exceeds the prescription's {limit} {unit} (prescription {prescription}, sha256 {sha256})"
)]
pub struct Exceeded {
    /// The layer (e.g. "stim-driver interlocks").
    pub layer: &'static str,
    /// The key or quantity.
    pub field: &'static str,
    /// Its value.
    pub value: u64,
    /// The prescription's bound (for a minimum IPI: the smallest allowed value).
    pub limit: u64,
    /// Unit.
    pub unit: &'static str,
    /// The prescription file.
    pub prescription: String,
    /// Its checksum.
    pub sha256: String,
}

/// Ceilings of one layer, to be held against the prescription; `None` = not a limit of
/// that layer.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ceilings {
    /// Amplitude ceiling, uA.
    pub amplitude_ua: Option<u32>,
    /// Phase width ceiling, us.
    pub width_us: Option<u32>,
    /// Charge-per-phase ceiling, nC.
    pub charge_nc: Option<u32>,
    /// Minimum inter-pulse interval, us.
    pub min_ipi_us: Option<u32>,
    /// The most pulses the layer lets through in any 1 s.
    pub pulses_per_s: Option<u64>,
}

/// The most pulses a limit of `max_pulses` in any `window_ms` lets through in any 1 s:
/// a 1 s interval splits into `ceil(1000 / window_ms)` pieces no longer than the window.
pub fn pulses_per_s(max_pulses: u32, window_ms: u32) -> u64 {
    u64::from(max_pulses) * 1000u64.div_ceil(u64::from(window_ms.max(1)))
}

impl Prescription {
    /// The first 6 bytes of [`Self::sha256`]: what each process publishes as the
    /// prescription it enforces (`TimingReport::prescription`), so that the supervisor can
    /// tell one prescription across the stack from several.
    pub fn fingerprint(&self) -> [u8; 6] {
        fingerprint_of(&self.sha256)
    }

    /// Reads and validates the file at `path`.
    ///
    /// The file must be one only root or this process's user can change (see
    /// [`PrescriptionError::Untrusted`]): the prescription bounds the current every layer
    /// may deliver, so a file another user of the machine could edit is no bound.
    pub fn load(path: &Path) -> Result<Self, PrescriptionError> {
        let read = |source| PrescriptionError::Read {
            path: path.to_owned(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(read)?;
        let dir = path
            .parent()
            .map(|d| {
                if d.as_os_str().is_empty() {
                    Path::new(".")
                } else {
                    d
                }
            })
            .and_then(|d| std::fs::metadata(d).ok());
        // SAFETY: geteuid has no preconditions and cannot fail.
        let euid = unsafe { libc::geteuid() };
        if let Some(why) = untrusted(&meta, dir.as_ref(), euid) {
            return Err(PrescriptionError::Untrusted {
                path: path.to_owned(),
                why,
                euid,
            });
        }
        let bytes = std::fs::read(path).map_err(read)?;
        let mut p = Self::parse_bytes(&bytes, &format!(" {}", path.display()))?;
        p.path = Some(path.to_owned());
        Ok(p)
    }

    /// Parses and validates the text of a prescription file.
    pub fn parse(text: &str) -> Result<Self, PrescriptionError> {
        Self::parse_bytes(text.as_bytes(), "")
    }

    fn parse_bytes(bytes: &[u8], at: &str) -> Result<Self, PrescriptionError> {
        let sha256 = sha256_hex(bytes);
        let text = std::str::from_utf8(bytes).map_err(|source| PrescriptionError::Utf8 {
            at: at.to_owned(),
            source,
        })?;
        let f: File = toml::from_str(text).map_err(|source| PrescriptionError::Parse {
            at: at.to_owned(),
            source,
        })?;
        if f.format != FORMAT {
            return Err(PrescriptionError::Format {
                at: at.to_owned(),
                found: f.format,
            });
        }
        let p = Prescription {
            label: f.label,
            max_amplitude_ua: f.max_amplitude_ua,
            max_phase_width_us: f.max_phase_width_us,
            max_charge_per_phase_nc: f.max_charge_per_phase_nc,
            min_ipi_us: f.min_ipi_us,
            max_pulses_per_s: f.max_pulses_per_s,
            electrode_area_cm2: f.electrode_area_cm2,
            current_density_acknowledged: f.current_density_acknowledged,
            sha256,
            path: None,
        };
        p.validate(at)?;
        Ok(p)
    }

    fn validate(&self, at: &str) -> Result<(), PrescriptionError> {
        let bad = |field: &'static str, value: String, why: String| {
            Err(PrescriptionError::Invalid {
                at: at.to_owned(),
                field,
                value,
                why,
            })
        };
        if !(1..=150_000).contains(&self.max_amplitude_ua) {
            return bad(
                "max_amplitude_ua",
                self.max_amplitude_ua.to_string(),
                "outside 1..=150000 (the protocol's 150 mA)".into(),
            );
        }
        if !(1..=1000).contains(&self.max_phase_width_us) {
            return bad(
                "max_phase_width_us",
                self.max_phase_width_us.to_string(),
                "outside 1..=1000".into(),
            );
        }
        let product = self.product_nc();
        if self.max_charge_per_phase_nc == 0 || u64::from(self.max_charge_per_phase_nc) > product {
            return bad(
                "max_charge_per_phase_nc",
                self.max_charge_per_phase_nc.to_string(),
                format!(
                    "must be 1..={product} (max_amplitude_ua x max_phase_width_us): a larger charge \
                     can never be reached, so it is a slip"
                ),
            );
        }
        if !(1000..=1_000_000).contains(&self.min_ipi_us) {
            return bad(
                "min_ipi_us",
                self.min_ipi_us.to_string(),
                "outside 1000..=1000000".into(),
            );
        }
        let fastest = 1_000_000 / self.min_ipi_us;
        if self.max_pulses_per_s == 0 || self.max_pulses_per_s > fastest {
            return bad(
                "max_pulses_per_s",
                self.max_pulses_per_s.to_string(),
                format!("must be 1..={fastest} (1 s / min_ipi_us)"),
            );
        }
        if let Some(a) = self.electrode_area_cm2 {
            if !(a.is_finite() && a > 0.0 && a <= 1000.0) {
                return bad(
                    "electrode_area_cm2",
                    a.to_string(),
                    "must be finite, > 0 and <= 1000".into(),
                );
            }
            if let Some(j) = self.rms_current_density_ma_per_cm2()
                && j > CURRENT_DENSITY_ATTENTION_MA_PER_CM2
                && !self.current_density_acknowledged
            {
                return bad(
                    "electrode_area_cm2",
                    a.to_string(),
                    format!(
                        "the r.m.s. current density at the ceilings is {j:.2} mA/cm², above IEC \
                         60601-2-10's {CURRENT_DENSITY_ATTENTION_MA_PER_CM2} mA/cm² attention level; \
                         set current_density_acknowledged = true only if that is intended"
                    ),
                );
            }
        }
        Ok(())
    }

    /// max_amplitude_ua x max_phase_width_us in nC.
    fn product_nc(&self) -> u64 {
        u64::from(self.max_amplitude_ua) * u64::from(self.max_phase_width_us) / 1000
    }

    /// The r.m.s. current density at the ceilings under the stated electrode, mA/cm²:
    /// `I * sqrt(2 * w * f) / A` (two phases of width `w` per pulse, `f` pulses per s).
    pub fn rms_current_density_ma_per_cm2(&self) -> Option<f64> {
        let area = self.electrode_area_cm2?;
        let i_ma = f64::from(self.max_amplitude_ua) / 1000.0;
        let duty =
            2.0 * f64::from(self.max_phase_width_us) * 1e-6 * f64::from(self.max_pulses_per_s);
        Some(i_ma * duty.sqrt() / area)
    }

    /// The charge density per phase at the charge ceiling, uC/cm².
    pub fn charge_density_uc_per_cm2(&self) -> Option<f64> {
        let area = self.electrode_area_cm2?;
        Some(f64::from(self.max_charge_per_phase_nc) / 1000.0 / area)
    }

    /// The file's name for messages.
    pub fn name(&self) -> String {
        self.path
            .as_ref()
            .map_or_else(|| "(text)".to_owned(), |p| p.display().to_string())
    }

    fn exceeded(
        &self,
        layer: &'static str,
        field: &'static str,
        value: u64,
        limit: u64,
        unit: &'static str,
    ) -> Exceeded {
        Exceeded {
            layer,
            field,
            value,
            limit,
            unit,
            prescription: self.name(),
            sha256: self.sha256.clone(),
        }
    }

    /// Checks one pulse: amplitude, phase width and charge per phase.
    pub fn check_pulse(
        &self,
        layer: &'static str,
        amplitude_ua: u32,
        width_us: u32,
    ) -> Result<(), Exceeded> {
        let charge_nc = u64::from(amplitude_ua) * u64::from(width_us) / 1000;
        self.check(
            layer,
            &Ceilings {
                amplitude_ua: Some(amplitude_ua),
                width_us: Some(width_us),
                charge_nc: Some(u32::try_from(charge_nc).unwrap_or(u32::MAX)),
                ..Ceilings::default()
            },
        )
    }

    /// Checks the ceilings of a layer: none may be looser than the prescription.
    pub fn check(&self, layer: &'static str, c: &Ceilings) -> Result<(), Exceeded> {
        if let Some(a) = c.amplitude_ua
            && a > self.max_amplitude_ua
        {
            return Err(self.exceeded(
                layer,
                "amplitude",
                a.into(),
                self.max_amplitude_ua.into(),
                "uA",
            ));
        }
        if let Some(w) = c.width_us
            && w > self.max_phase_width_us
        {
            return Err(self.exceeded(
                layer,
                "phase width",
                w.into(),
                self.max_phase_width_us.into(),
                "us",
            ));
        }
        if let Some(q) = c.charge_nc
            && q > self.max_charge_per_phase_nc
        {
            return Err(self.exceeded(
                layer,
                "charge per phase",
                q.into(),
                self.max_charge_per_phase_nc.into(),
                "nC",
            ));
        }
        if let Some(ipi) = c.min_ipi_us
            && ipi < self.min_ipi_us
        {
            // The bound of a minimum is the smallest allowed value.
            return Err(Exceeded {
                field: "minimum IPI (shorter than)",
                ..self.exceeded(layer, "", ipi.into(), self.min_ipi_us.into(), "us")
            });
        }
        if let Some(n) = c.pulses_per_s
            && n > u64::from(self.max_pulses_per_s)
        {
            return Err(self.exceeded(
                layer,
                "pulses in any 1 s",
                n,
                self.max_pulses_per_s.into(),
                "pulses",
            ));
        }
        Ok(())
    }

    /// A one-line summary for logs.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "prescription {} (sha256 {}): {} uA, {} us per phase, {} nC per phase, IPI >= {} us, <= {} pulses/s",
            self.name(),
            self.sha256,
            self.max_amplitude_ua,
            self.max_phase_width_us,
            self.max_charge_per_phase_nc,
            self.min_ipi_us,
            self.max_pulses_per_s
        );
        if let (Some(a), Some(j), Some(q)) = (
            self.electrode_area_cm2,
            self.rms_current_density_ma_per_cm2(),
            self.charge_density_uc_per_cm2(),
        ) {
            s.push_str(&format!(
                ", electrode {a} cm²: {j:.3} mA/cm² r.m.s., {q:.3} uC/cm² per phase"
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    /// A prescription only root or the process's user can change loads; one its group or
    /// others could write, or another user owns, or in a directory others may write
    /// without the sticky bit, is refused before it is read.
    #[test]
    fn a_prescription_others_could_change_is_refused() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = fes_testkit::Scratch::new("prescription");
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let file = dir.join("prescription.toml");
        std::fs::write(&file, DOSE).unwrap();
        let mode = |m: u32| std::fs::set_permissions(&file, std::fs::Permissions::from_mode(m));
        mode(0o644).unwrap();
        Prescription::load(&file).unwrap();
        for m in [0o664, 0o646, 0o666] {
            mode(m).unwrap();
            let e = Prescription::load(&file).unwrap_err();
            assert!(
                matches!(&e, PrescriptionError::Untrusted { why, .. } if why.contains("mode")),
                "{m:o}: {e}"
            );
        }
        mode(0o644).unwrap();
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = Prescription::load(&file).unwrap_err();
        assert!(
            matches!(&e, PrescriptionError::Untrusted { why, .. } if why.contains("directory")),
            "{e}"
        );
        // /tmp's way: world-writable but sticky (others cannot replace a file they do not own).
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o1777)).unwrap();
        Prescription::load(&file).unwrap();
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        // Owned by another user (only root can give a file away, so only root shows it).
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } == 0 {
            let c = std::ffi::CString::new(file.as_os_str().as_encoded_bytes()).unwrap();
            // SAFETY: chown on a path this test created; the string outlives the call.
            assert_eq!(unsafe { libc::chown(c.as_ptr(), 65534, 65534) }, 0);
            let e = Prescription::load(&file).unwrap_err();
            assert!(
                matches!(&e, PrescriptionError::Untrusted { why, .. } if why.contains("owned")),
                "{e}"
            );
        }
    }

    use super::*;

    const DOSE: &str = r#"format = "fes-prescription/1"
max_amplitude_ua = 20000
max_phase_width_us = 200
max_charge_per_phase_nc = 4000
min_ipi_us = 2000
max_pulses_per_s = 100
"#;

    #[test]
    fn the_dose_parses_with_its_checksum() {
        let p = Prescription::parse(DOSE).unwrap();
        assert_eq!(p.max_amplitude_ua, 20_000);
        assert_eq!(p.sha256, sha256_hex(DOSE.as_bytes()));
        assert_eq!(p.sha256.len(), 64);
        p.check_pulse("rt-core", 20_000, 200).unwrap();
    }

    #[test]
    fn a_5x_amplitude_slip_is_refused() {
        let p = Prescription::parse(DOSE).unwrap();
        let e = p.check_pulse("rt-core pulse", 100_000, 200).unwrap_err();
        assert_eq!((e.field, e.value, e.limit), ("amplitude", 100_000, 20_000));
        // The charge alone: 19 mA x 250 us is under the amplitude ceiling but not the width.
        let e = p.check_pulse("x", 19_000, 250).unwrap_err();
        assert_eq!(e.field, "phase width");
        let p = Prescription::parse(&DOSE.replace("4000", "3000")).unwrap();
        let e = p.check_pulse("x", 20_000, 200).unwrap_err();
        assert_eq!(
            (e.field, e.value, e.limit),
            ("charge per phase", 4000, 3000)
        );
    }

    #[test]
    fn ceilings_of_a_layer_are_checked() {
        let p = Prescription::parse(DOSE).unwrap();
        let ok = Ceilings {
            amplitude_ua: Some(20_000),
            width_us: Some(200),
            charge_nc: Some(4000),
            min_ipi_us: Some(2000),
            pulses_per_s: Some(pulses_per_s(100, 1000)),
        };
        p.check("l", &ok).unwrap();
        let ipi = Ceilings {
            min_ipi_us: Some(1999),
            ..ok
        };
        assert!(p.check("l", &ipi).is_err());
        // 60 pulses per 500 ms is 120 in some 1 s.
        let rate = Ceilings {
            pulses_per_s: Some(pulses_per_s(60, 500)),
            ..ok
        };
        assert_eq!(p.check("l", &rate).unwrap_err().value, 120);
    }

    #[test]
    fn invalid_prescriptions_say_why() {
        for (from, to, field) in [
            (
                "max_amplitude_ua = 20000",
                "max_amplitude_ua = 0",
                "max_amplitude_ua",
            ),
            (
                "max_phase_width_us = 200",
                "max_phase_width_us = 2000",
                "max_phase_width_us",
            ),
            ("= 4000", "= 40000", "max_charge_per_phase_nc"),
            ("min_ipi_us = 2000", "min_ipi_us = 500", "min_ipi_us"),
            (
                "max_pulses_per_s = 100",
                "max_pulses_per_s = 501",
                "max_pulses_per_s",
            ),
        ] {
            match Prescription::parse(&DOSE.replace(from, to)) {
                Err(PrescriptionError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{to}: {other:?}"),
            }
        }
        assert!(matches!(
            Prescription::parse(&DOSE.replace("/1", "/2")),
            Err(PrescriptionError::Format { .. })
        ));
        assert!(matches!(
            Prescription::parse(&format!("{DOSE}extra = 1\n")),
            Err(PrescriptionError::Parse { .. })
        ));
    }

    #[test]
    fn current_density_above_2_ma_per_cm2_needs_acknowledging() {
        // 20 mA x sqrt(2 x 200 us x 100 /s) = 4 mA r.m.s.: 2 cm² gives 2 mA/cm² (allowed),
        // 1.5 cm² 2.67 mA/cm² (refused unless acknowledged).
        let p = Prescription::parse(&format!("{DOSE}electrode_area_cm2 = 2.0\n")).unwrap();
        assert!((p.rms_current_density_ma_per_cm2().unwrap() - 2.0).abs() < 1e-9);
        assert!((p.charge_density_uc_per_cm2().unwrap() - 2.0).abs() < 1e-9);
        let small = format!("{DOSE}electrode_area_cm2 = 1.5\n");
        match Prescription::parse(&small) {
            Err(PrescriptionError::Invalid { field, why, .. }) => {
                assert_eq!(field, "electrode_area_cm2");
                assert!(why.contains("2.67 mA/cm²"), "{why}");
            }
            other => panic!("{other:?}"),
        }
        Prescription::parse(&format!("{small}current_density_acknowledged = true\n")).unwrap();
    }
}
