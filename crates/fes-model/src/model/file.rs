//! The model file: pretty JSON, schema `fes-lmn/1` (format in docs/model.md).
//!
//! Loading validates everything and rejects a bad file with an error that names the field
//! (`units[2].eigenvalues[1]: ...`); a JSON syntax error quotes the offending line (JSON has
//! no NaN or Infinity, so such values surface there). `load` also requires every local
//! model to be stable; `load_allow_unstable` skips only that requirement and returns the
//! per-unit stability as data (analysis and `modify --stabilise` must open an unstable model
//! to repair it). Reading and writing files (`load`, `load_allow_unstable`, `save`) needs the
//! `std` feature; [`from_json_str`] and [`to_json_string`] work on text in every build.

use super::arx::{ArxUnit, MAX_ARX_ORDER};
#[cfg(feature = "std")]
use super::lmn::UnitStability;
use super::lmn::{Lmn, LmnError, LocalModelSet, Provenance, Stability, Structure};
use super::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use super::scheduling::SchedulingSpec;
use super::validity::ValidityFunctions;
use alloc::{
    format,
    string::{String, ToString},
    vec,
    vec::Vec,
};
use serde_json::{Map, Value, json};
#[cfg(feature = "std")]
use std::path::{Path, PathBuf};

/// The schema version string this code reads and writes.
pub const SCHEMA: &str = "fes-lmn/1";

/// Why a model file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be read or written (`std` only).
    #[cfg(feature = "std")]
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The text is not valid JSON.
    #[error(
        "invalid JSON at line {line}, column {column}: {message}; the line reads: {text:?} (note: NaN and Infinity are not valid JSON numbers)"
    )]
    Syntax {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// The parser's message.
        message: String,
        /// The offending line.
        text: String,
    },
    /// A field is missing or invalid (the message names it).
    #[error(transparent)]
    Invalid(#[from] LmnError),
}

fn bad(field: impl Into<String>, problem: impl Into<String>) -> FileError {
    FileError::Invalid(LmnError::Invalid {
        field: field.into(),
        problem: problem.into(),
    })
}

/// Loads a model and requires every local model to be stable (`std` only).
#[cfg(feature = "std")]
pub fn load(path: impl AsRef<Path>) -> Result<Lmn, FileError> {
    from_json_str(&read(path.as_ref())?, Stability::Require)
}

/// Loads a model without the stability requirement (everything else is still validated) and
/// returns the per-unit stability report (`std` only).
#[cfg(feature = "std")]
pub fn load_allow_unstable(path: impl AsRef<Path>) -> Result<(Lmn, Vec<UnitStability>), FileError> {
    let lmn = from_json_str(&read(path.as_ref())?, Stability::Report)?;
    let report = lmn.stability();
    Ok((lmn, report))
}

/// Writes a model as pretty JSON (validated first, stability not required; `std` only).
#[cfg(feature = "std")]
pub fn save(lmn: &Lmn, path: impl AsRef<Path>) -> Result<(), FileError> {
    let text = to_json_string(lmn)?;
    std::fs::write(path.as_ref(), text).map_err(|source| FileError::Io {
        path: path.as_ref().to_path_buf(),
        source,
    })
}

#[cfg(feature = "std")]
fn read(path: &Path) -> Result<String, FileError> {
    std::fs::read_to_string(path).map_err(|source| FileError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The file text of a model (validated first, stability not required).
pub fn to_json_string(lmn: &Lmn) -> Result<String, FileError> {
    lmn.validate(Stability::Report)?;
    let sched = match lmn.scheduling {
        SchedulingSpec::Input {
            gain,
            natural_frequency_rad_s,
            damping,
        } => json!({
            "kind": "input", "gain": gain,
            "natural_frequency_rad_s": natural_frequency_rad_s, "damping": damping
        }),
        SchedulingSpec::Output => json!({ "kind": "output" }),
    };
    let zo = lmn.zero_offsets;
    let with_offsets = |mut o: Map<String, Value>, dx: &[f64; 2], dy: f64| {
        if !zo {
            o.insert("dx".into(), json!(dx));
            o.insert("dy".into(), json!(dy));
        }
        Value::Object(o)
    };
    let obj = |v: Value| match v {
        Value::Object(m) => m,
        _ => Map::new(),
    };
    let (units, reference_unit): (Vec<Value>, Option<usize>) = match &lmn.local {
        LocalModelSet::SsDirect(u) => (
            u.iter()
                .map(|m| with_offsets(obj(json!({"a": m.a, "b": m.b, "c": m.c})), &m.dx, m.dy))
                .collect(),
            None,
        ),
        LocalModelSet::SsEigLocal(u) => (
            u.iter()
                .map(|m| {
                    with_offsets(
                        obj(json!({"eigenvalues": m.eigenvalues,
                            "eigenvector_angles_rad": m.eigenvector_angles, "b": m.b, "c": m.c})),
                        &m.dx,
                        m.dy,
                    )
                })
                .collect(),
            None,
        ),
        LocalModelSet::SsEigCommon {
            units,
            reference_unit,
        } => (
            units
                .iter()
                .map(|m| {
                    with_offsets(
                        obj(json!({"eigenvalues": m.eigenvalues, "b": m.b, "c": m.c})),
                        &m.dx,
                        m.dy,
                    )
                })
                .collect(),
            Some(*reference_unit),
        ),
        LocalModelSet::ArxShift { order, units } | LocalModelSet::ArxDelta { order, units } => (
            units
                .iter()
                .map(|m| {
                    let mut o = obj(json!({"a": m.a[..*order], "b": m.b[..*order]}));
                    if !zo {
                        o.insert("d".into(), json!(m.d));
                    }
                    Value::Object(o)
                })
                .collect(),
            None,
        ),
    };
    let mut root = Map::new();
    root.insert("schema".into(), json!(SCHEMA));
    root.insert("ts_s".into(), json!(lmn.ts));
    root.insert("delay_samples".into(), json!(lmn.delay));
    root.insert("scheduling".into(), sched);
    root.insert("order".into(), json!(lmn.validity.order()));
    root.insert("knots".into(), json!(lmn.validity.knots()));
    root.insert("structure".into(), json!(lmn.structure().name()));
    root.insert("zero_offsets".into(), json!(zo));
    if let Some(r) = reference_unit {
        root.insert("reference_unit".into(), json!(r));
    }
    root.insert("force_scale_n".into(), json!(lmn.force_scale_n));
    root.insert("units".into(), Value::Array(units));
    root.insert(
        "provenance".into(),
        serde_json::to_value(&lmn.provenance).map_err(|e| bad("provenance", e.to_string()))?,
    );
    serde_json::to_string_pretty(&Value::Object(root)).map_err(|e| bad("(model)", e.to_string()))
}

/// Parses and validates a model file's text.
pub fn from_json_str(text: &str, stability: Stability) -> Result<Lmn, FileError> {
    let root: Value = serde_json::from_str(text).map_err(|e| {
        let line = e.line();
        FileError::Syntax {
            line,
            column: e.column(),
            message: e.to_string(),
            text: text
                .lines()
                .nth(line.saturating_sub(1))
                .unwrap_or("")
                .trim()
                .to_string(),
        }
    })?;
    let root = Obj::new(&root, "")?;
    let schema = root.str("schema")?;
    if schema != SCHEMA {
        return Err(bad(
            "schema",
            format!("unsupported schema {schema:?} (this build reads {SCHEMA:?})"),
        ));
    }
    let ts = root.num("ts_s")?;
    let delay = root.usize("delay_samples")?;
    let scheduling = {
        let s = root.obj("scheduling")?;
        match s.str("kind")? {
            "input" => {
                s.only(&["kind", "gain", "natural_frequency_rad_s", "damping"])?;
                SchedulingSpec::Input {
                    gain: s.num("gain")?,
                    natural_frequency_rad_s: s.num("natural_frequency_rad_s")?,
                    damping: s.num("damping")?,
                }
            }
            "output" => {
                s.only(&["kind"])?;
                SchedulingSpec::Output
            }
            other => {
                return Err(bad(
                    "scheduling.kind",
                    format!("unknown kind {other:?} (expected \"input\" or \"output\")"),
                ));
            }
        }
    };
    let order = root.usize("order")?;
    let knots = root.nums("knots")?;
    let structure: Structure = root
        .str("structure")?
        .parse()
        .map_err(|e: String| bad("structure", e))?;
    let zero_offsets = root.bool("zero_offsets")?;
    let force_scale_n = root.num("force_scale_n")?;
    let units = root.arr("units")?;
    if knots.len() != units.len() + order {
        return Err(bad(
            "knots",
            format!(
                "{} knots given for {} units of order {order}: the knot count must be units + order = {}",
                knots.len(),
                units.len(),
                units.len() + order
            ),
        ));
    }
    let validity =
        ValidityFunctions::from_knots(&knots, order).map_err(|e| bad("knots", e.to_string()))?;
    let mut allowed_root = vec![
        "schema",
        "ts_s",
        "delay_samples",
        "scheduling",
        "order",
        "knots",
        "structure",
        "zero_offsets",
        "force_scale_n",
        "units",
        "provenance",
    ];
    if structure == Structure::SsEigCommon {
        allowed_root.push("reference_unit");
    }
    root.only(&allowed_root)?;
    let unit_objs: Vec<Obj> = units
        .iter()
        .enumerate()
        .map(|(i, u)| Obj::new(u, &format!("units[{i}]")))
        .collect::<Result<_, _>>()?;
    let offsets = |u: &Obj| -> Result<([f64; 2], f64), FileError> {
        if zero_offsets && !u.has("dx") && !u.has("dy") {
            Ok(([0.0; 2], 0.0))
        } else {
            Ok((u.vec2("dx")?, u.num("dy")?))
        }
    };
    let ss_keys = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut k = vec!["b", "c", "dx", "dy"];
        k.extend_from_slice(extra);
        k
    };
    let local = match structure {
        Structure::SsDirect => LocalModelSet::SsDirect(
            unit_objs
                .iter()
                .map(|u| {
                    u.only(&ss_keys(&["a"]))?;
                    let rows = u.arr("a")?;
                    if rows.len() != 2 {
                        return Err(bad(
                            u.path("a"),
                            format!("expected 2 rows, found {}", rows.len()),
                        ));
                    }
                    let r0 = vec_n(&rows[0], &format!("{}[0]", u.path("a")), 2)?;
                    let r1 = vec_n(&rows[1], &format!("{}[1]", u.path("a")), 2)?;
                    let (dx, dy) = offsets(u)?;
                    Ok(SsLocalModel {
                        a: [[r0[0], r0[1]], [r1[0], r1[1]]],
                        b: u.vec2("b")?,
                        c: u.vec2("c")?,
                        dx,
                        dy,
                    })
                })
                .collect::<Result<_, FileError>>()?,
        ),
        Structure::SsEigLocal => LocalModelSet::SsEigLocal(
            unit_objs
                .iter()
                .map(|u| {
                    u.only(&ss_keys(&["eigenvalues", "eigenvector_angles_rad"]))?;
                    let (dx, dy) = offsets(u)?;
                    Ok(EigLocalUnit {
                        eigenvalues: u.vec2("eigenvalues")?,
                        eigenvector_angles: u.vec2("eigenvector_angles_rad")?,
                        b: u.vec2("b")?,
                        c: u.vec2("c")?,
                        dx,
                        dy,
                    })
                })
                .collect::<Result<_, FileError>>()?,
        ),
        Structure::SsEigCommon => LocalModelSet::SsEigCommon {
            units: unit_objs
                .iter()
                .map(|u| {
                    u.only(&ss_keys(&["eigenvalues"]))?;
                    let (dx, dy) = offsets(u)?;
                    Ok(EigCommonUnit {
                        eigenvalues: u.vec2("eigenvalues")?,
                        b: u.vec2("b")?,
                        c: u.vec2("c")?,
                        dx,
                        dy,
                    })
                })
                .collect::<Result<_, FileError>>()?,
            reference_unit: root.usize("reference_unit")?,
        },
        Structure::ArxShift | Structure::ArxDelta => {
            let first = unit_objs.first().ok_or_else(|| bad("units", "no units"))?;
            let n = first.arr("a")?.len();
            if !(1..=MAX_ARX_ORDER).contains(&n) {
                return Err(bad(
                    first.path("a"),
                    format!("ARX order (length of a) {n} is outside 1..={MAX_ARX_ORDER}"),
                ));
            }
            let units = unit_objs
                .iter()
                .map(|u| {
                    u.only(&["a", "b", "d"])?;
                    let a = vec_n(u.get("a")?, &u.path("a"), n)?;
                    let b = vec_n(u.get("b")?, &u.path("b"), n)?;
                    let d = if zero_offsets && !u.has("d") {
                        0.0
                    } else {
                        u.num("d")?
                    };
                    let mut m = ArxUnit::zero();
                    m.a[..n].copy_from_slice(&a);
                    m.b[..n].copy_from_slice(&b);
                    m.d = d;
                    Ok(m)
                })
                .collect::<Result<_, FileError>>()?;
            if structure == Structure::ArxShift {
                LocalModelSet::ArxShift { order: n, units }
            } else {
                LocalModelSet::ArxDelta { order: n, units }
            }
        }
    };
    let provenance = match root.map.get("provenance") {
        None | Some(Value::Null) => Provenance::default(),
        Some(v) => {
            let p = Obj::new(v, "provenance")?;
            for key in ["train_mspe", "train_msse", "test_msse", "fit_seconds"] {
                if let Some(x) = p.map.get(key)
                    && !x.is_null()
                {
                    p.num(key)?;
                }
            }
            serde_json::from_value(v.clone()).map_err(|e| bad("provenance", e.to_string()))?
        }
    };
    let lmn = Lmn {
        ts,
        delay,
        scheduling,
        validity,
        local,
        zero_offsets,
        force_scale_n,
        provenance,
    };
    lmn.validate(stability)?;
    if stability == Stability::Report {
        // `Require` checks it inside `validate`; a file opened for repair must still run.
        lmn.check_rest_state()?;
    }
    Ok(lmn)
}

/// A JSON object with its path, for field-naming errors.
struct Obj<'a> {
    map: &'a Map<String, Value>,
    prefix: String,
}

impl<'a> Obj<'a> {
    fn new(v: &'a Value, path: &str) -> Result<Self, FileError> {
        match v {
            Value::Object(map) => Ok(Self {
                map,
                prefix: path.to_string(),
            }),
            other => Err(bad(
                if path.is_empty() { "(file)" } else { path },
                format!("expected an object, found {}", kind(other)),
            )),
        }
    }

    fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.prefix)
        }
    }

    fn has(&self, key: &str) -> bool {
        self.map.contains_key(key)
    }

    fn get(&self, key: &str) -> Result<&'a Value, FileError> {
        self.map
            .get(key)
            .ok_or_else(|| bad(self.path(key), "missing field"))
    }

    fn only(&self, allowed: &[&str]) -> Result<(), FileError> {
        for k in self.map.keys() {
            if !allowed.contains(&k.as_str()) {
                return Err(bad(
                    self.path(k),
                    format!("unknown field (expected one of: {})", allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }

    fn obj(&self, key: &str) -> Result<Obj<'a>, FileError> {
        Obj::new(self.get(key)?, &self.path(key))
    }

    fn str(&self, key: &str) -> Result<&'a str, FileError> {
        self.get(key)?.as_str().ok_or_else(|| {
            bad(
                self.path(key),
                format!("expected a string, found {}", kind(&self.map[key])),
            )
        })
    }

    fn bool(&self, key: &str) -> Result<bool, FileError> {
        self.get(key)?.as_bool().ok_or_else(|| {
            bad(
                self.path(key),
                format!("expected true or false, found {}", kind(&self.map[key])),
            )
        })
    }

    fn num(&self, key: &str) -> Result<f64, FileError> {
        number(self.get(key)?, &self.path(key))
    }

    fn usize(&self, key: &str) -> Result<usize, FileError> {
        let v = self.get(key)?;
        v.as_u64()
            .and_then(|x| usize::try_from(x).ok())
            .ok_or_else(|| {
                bad(
                    self.path(key),
                    format!("expected a non-negative integer, found {}", kind(v)),
                )
            })
    }

    fn arr(&self, key: &str) -> Result<&'a Vec<Value>, FileError> {
        let v = self.get(key)?;
        v.as_array().ok_or_else(|| {
            bad(
                self.path(key),
                format!("expected an array, found {}", kind(v)),
            )
        })
    }

    fn nums(&self, key: &str) -> Result<Vec<f64>, FileError> {
        let p = self.path(key);
        self.arr(key)?
            .iter()
            .enumerate()
            .map(|(i, v)| number(v, &format!("{p}[{i}]")))
            .collect()
    }

    fn vec2(&self, key: &str) -> Result<[f64; 2], FileError> {
        let v = vec_n(self.get(key)?, &self.path(key), 2)?;
        Ok([v[0], v[1]])
    }
}

fn vec_n(v: &Value, path: &str, n: usize) -> Result<Vec<f64>, FileError> {
    let a = v.as_array().ok_or_else(|| {
        bad(
            path,
            format!("expected an array of {n} numbers, found {}", kind(v)),
        )
    })?;
    if a.len() != n {
        return Err(bad(
            path,
            format!("expected {n} numbers, found {}", a.len()),
        ));
    }
    a.iter()
        .enumerate()
        .map(|(i, x)| number(x, &format!("{path}[{i}]")))
        .collect()
}

fn number(v: &Value, path: &str) -> Result<f64, FileError> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        Some(x) => Err(bad(path, format!("{x} is not a finite number"))),
        None => Err(bad(
            path,
            format!("expected a finite number, found {}", kind(v))
                + if v.is_null() {
                    " (NaN or a missing value?)"
                } else {
                    ""
                },
        )),
    }
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}
