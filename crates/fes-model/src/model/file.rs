//! The model file: pretty JSON, schema `fes-lmn/1` (format in docs/model.md, section "Model
//! file").
//!
//! Reading goes in three steps. The text is parsed as JSON first: a syntax error quotes the
//! offending line (JSON has no NaN or Infinity, so such values surface there). The value is
//! then deserialised into private serde structs with `deny_unknown_fields`, one per part of
//! the format (`ModelDoc`, `SchedulingDoc`, one unit struct per local-model form): a value of
//! the wrong type, a missing or an unknown field is reported with its path
//! (`units[2].b: expected 2 numbers, found 1`; a missing field with the path of its object
//! and its name, ``units[2]: missing field `c` ``). Last, the structs are converted into an
//! [`Lmn`] and [`Lmn::validate`] checks every value, naming the field
//! (`units[2].eigenvalues[1]: ...`). The writer fills the same structs, so the two cannot
//! drift.
//!
//! `load` also requires every local model to be stable; `load_allow_unstable` skips only that
//! requirement and returns the per-unit stability as data (analysis and `modify --stabilise`
//! must open an unstable model to repair it). Reading and writing files (`load`,
//! `load_allow_unstable`, `save`) needs the `std` feature; [`from_json_str`] and
//! [`to_json_string`] work on text in every build.

use super::arx::{ArxUnit, MAX_ARX_ORDER};
#[cfg(feature = "std")]
use super::lmn::UnitStability;
use super::lmn::{Lmn, LmnError, LocalModelSet, Provenance, Stability, Structure};
use super::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use super::scheduling::{SchedulingInput, SchedulingSpec};
use super::validity::ValidityFunctions;
use alloc::{
    format,
    string::{String, ToString},
    vec::Vec,
};
use core::fmt;
use core::marker::PhantomData;
use serde::de::{self, Deserializer, IgnoredAny, SeqAccess, Unexpected, Visitor};
use serde::{Deserialize, Serialize};
use serde_json::Value;
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
    /// A field is missing or of the wrong type, or the model cannot be encoded (`field`
    /// is `(file)` for the top level, `(model)` when writing).
    #[error("{field}: {source}")]
    Json {
        /// The field, e.g. `units[2].b`.
        field: String,
        /// serde_json's error.
        #[source]
        source: serde_json::Error,
    },
}

fn json(field: &str) -> impl FnOnce(serde_json::Error) -> FileError + '_ {
    move |source| FileError::Json {
        field: field.into(),
        source,
    }
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
    let zo = lmn.zero_offsets;
    let value = match &lmn.local {
        LocalModelSet::SsDirect(u) => doc(lmn, u.iter().map(|u| SsDirectDoc::new(u, zo)), None),
        LocalModelSet::SsEigLocal(u) => doc(lmn, u.iter().map(|u| EigLocalDoc::new(u, zo)), None),
        LocalModelSet::SsEigCommon {
            units,
            reference_unit,
        } => {
            let units = units.iter().map(|u| EigCommonDoc::new(u, zo));
            doc(lmn, units, Some(*reference_unit))
        }
        LocalModelSet::ArxShift { order, units } | LocalModelSet::ArxDelta { order, units } => {
            doc(lmn, units.iter().map(|u| ArxDoc::new(u, *order, zo)), None)
        }
    }?;
    serde_json::to_string_pretty(&value).map_err(json("(model)"))
}

/// The document of `lmn` with its units already converted, as a JSON value: written from
/// the value, every object's keys come out in sorted order (serde_json's map is sorted), as
/// model files have always been written.
fn doc<U: Serialize>(
    lmn: &Lmn,
    units: impl Iterator<Item = U>,
    reference_unit: Option<usize>,
) -> Result<Value, FileError> {
    serde_json::to_value(ModelDoc::new(lmn, units, reference_unit)).map_err(json("(model)"))
}

/// Parses and validates a model file's text.
pub fn from_json_str(text: &str, stability: Stability) -> Result<Lmn, FileError> {
    let root = parse(text)?;
    let head: Head = typed(&root)?;
    if head.schema != SCHEMA {
        return Err(bad(
            "schema",
            format!(
                "unsupported schema {:?} (this build reads {SCHEMA:?})",
                head.schema
            ),
        ));
    }
    let structure: Structure = head.structure.parse().map_err(LmnError::Structure)?;
    let lmn = match structure {
        Structure::SsDirect => typed::<ModelDoc<SsDirectDoc>>(&root)?.into_lmn(),
        Structure::SsEigLocal => typed::<ModelDoc<EigLocalDoc>>(&root)?.into_lmn(),
        Structure::SsEigCommon => typed::<ModelDoc<EigCommonDoc>>(&root)?.into_lmn(),
        Structure::ArxShift | Structure::ArxDelta => typed::<ModelDoc<ArxDoc>>(&root)?.into_lmn(),
    }?;
    lmn.validate(stability)?;
    if stability == Stability::Report {
        // `Require` checks it inside `validate`; a file opened for repair must still run.
        lmn.check_rest_state()?;
    }
    Ok(lmn)
}

/// The JSON value of the text, or the syntax error with the offending line.
fn parse(text: &str) -> Result<Value, FileError> {
    serde_json::from_str(text).map_err(|e| {
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
    })
}

/// Deserialises `T` from the parsed file; an error names the path of the offending value
/// (`units[2].b`; `(file)` for the top level).
fn typed<'a, T: Deserialize<'a>>(root: &'a Value) -> Result<T, FileError> {
    serde_path_to_error::deserialize(root).map_err(|e| {
        let field = if e.path().iter().next().is_none() {
            "(file)".to_string()
        } else {
            e.path().to_string()
        };
        json(&field)(e.into_inner())
    })
}

/// The two fields read before the rest: `schema`, checked first so that a file of another
/// version is reported as such, and `structure`, which selects the unit type of
/// [`ModelDoc`]. The only struct that ignores other fields: [`ModelDoc`] reads them all.
#[derive(Deserialize)]
#[serde(expecting = "a model file (a JSON object)")]
struct Head {
    schema: String,
    structure: String,
}

/// The whole file (docs/model.md, "Model file"); `U` is the unit of the local-model form
/// that `structure` names.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields, expecting = "a model file (a JSON object)")]
struct ModelDoc<U> {
    schema: String,
    ts_s: Num,
    delay_samples: Count,
    scheduling: SchedulingDoc,
    order: Count,
    knots: Vec<Num>,
    structure: Structure,
    zero_offsets: bool,
    /// `ss-eig-common` only: the unit whose b is fixed at (1, 1).
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    reference_unit: Option<Count>,
    force_scale_n: Num,
    units: Vec<U>,
    /// Absent or null reads as empty; always written.
    #[serde(default)]
    provenance: Option<Provenance>,
}

impl<U> ModelDoc<U> {
    /// The document of `lmn`, whose units are already converted.
    fn new(lmn: &Lmn, units: impl Iterator<Item = U>, reference_unit: Option<usize>) -> Self {
        Self {
            schema: SCHEMA.to_string(),
            ts_s: Num(lmn.ts),
            delay_samples: Count(lmn.delay),
            scheduling: lmn.scheduling.into(),
            order: Count(lmn.validity.order()),
            knots: lmn.validity.knots().iter().map(|k| Num(*k)).collect(),
            structure: lmn.structure(),
            zero_offsets: lmn.zero_offsets,
            reference_unit: reference_unit.map(Count),
            force_scale_n: Num(lmn.force_scale_n),
            units: units.collect(),
            provenance: Some(lmn.provenance.clone()),
        }
    }

    /// The model (not yet validated): the common parts here, the units by their form.
    fn into_lmn(self) -> Result<Lmn, FileError>
    where
        U: UnitDoc,
    {
        let validity = validity(&self.knots, self.order.0, self.units.len())?;
        if self.reference_unit.is_some() && self.structure != Structure::SsEigCommon {
            return Err(bad(
                "reference_unit",
                format!(
                    "unknown field for structure {} (only ss-eig-common has a reference unit)",
                    self.structure
                ),
            ));
        }
        let scheduling = self.scheduling.into_spec()?;
        let local = U::local(
            self.units,
            self.structure,
            self.zero_offsets,
            self.reference_unit.map(|r| r.0),
        )?;
        Ok(Lmn {
            ts: self.ts_s.0,
            delay: self.delay_samples.0,
            scheduling,
            validity,
            local,
            zero_offsets: self.zero_offsets,
            force_scale_n: self.force_scale_n.0,
            provenance: self.provenance.unwrap_or_default(),
        })
    }
}

/// The validity functions of `knots` and `order` for `units` units (the count must be
/// units + order; [`ValidityFunctions::from_knots`] checks the rest).
fn validity(
    knots: &[Num],
    order: usize,
    units: usize,
) -> Result<ValidityFunctions<f64>, FileError> {
    if units.checked_add(order) != Some(knots.len()) {
        return Err(bad(
            "knots",
            format!(
                "{} knots given for {units} units of order {order}: the knot count must be units + order = {}",
                knots.len(),
                units.saturating_add(order)
            ),
        ));
    }
    let knots: Vec<f64> = knots.iter().map(|k| k.0).collect();
    ValidityFunctions::from_knots(&knots, order).map_err(|e| LmnError::Knots(e).into())
}

/// `scheduling`: `kind` selects the form, whose numbers are the other fields. A struct with
/// optional fields rather than a serde enum tagged by `kind`: serde reads a tagged enum from a
/// buffered copy, so an error inside would name only `scheduling`, not the field.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SchedulingDoc {
    kind: SchedulingKind,
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    gain: Option<Num>,
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    natural_frequency_rad_s: Option<Num>,
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    damping: Option<Num>,
    /// Input scheduling: which pulse train the prefilter filters; absent = `delayed` (every
    /// file written before the choice existed), written only when `undelayed`.
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    scheduling_input: Option<SchedulingInput>,
}

/// `scheduling.kind`.
#[derive(Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum SchedulingKind {
    /// Input scheduling: `gain`, `natural_frequency_rad_s` and `damping` are required.
    Input,
    /// Output scheduling: no other field.
    Output,
}

impl From<SchedulingSpec> for SchedulingDoc {
    fn from(s: SchedulingSpec) -> Self {
        match s {
            SchedulingSpec::Input {
                gain,
                natural_frequency_rad_s,
                damping,
                scheduling_input,
            } => Self {
                kind: SchedulingKind::Input,
                gain: Some(Num(gain)),
                natural_frequency_rad_s: Some(Num(natural_frequency_rad_s)),
                damping: Some(Num(damping)),
                scheduling_input: (scheduling_input != SchedulingInput::Delayed)
                    .then_some(scheduling_input),
            },
            SchedulingSpec::Output => Self {
                kind: SchedulingKind::Output,
                gain: None,
                natural_frequency_rad_s: None,
                damping: None,
                scheduling_input: None,
            },
        }
    }
}

impl SchedulingDoc {
    /// The specification: the fields of the kind present, no other.
    fn into_spec(self) -> Result<SchedulingSpec, FileError> {
        let fields = [
            ("gain", self.gain),
            ("natural_frequency_rad_s", self.natural_frequency_rad_s),
            ("damping", self.damping),
        ];
        if self.kind == SchedulingKind::Output {
            if self.scheduling_input.is_some() {
                return Err(bad(
                    "scheduling.scheduling_input",
                    "unknown field for kind \"output\" (it has no other field)",
                ));
            }
            return match fields.iter().find(|(_, v)| v.is_some()) {
                Some((name, _)) => Err(bad(
                    format!("scheduling.{name}"),
                    "unknown field for kind \"output\" (it has no other field)",
                )),
                None => Ok(SchedulingSpec::Output),
            };
        }
        let [gain, natural_frequency_rad_s, damping] = fields.map(|(name, v)| {
            v.map(|v| v.0)
                .ok_or_else(|| bad("scheduling", format!("missing field `{name}`")))
        });
        Ok(SchedulingSpec::Input {
            gain: gain?,
            natural_frequency_rad_s: natural_frequency_rad_s?,
            damping: damping?,
            scheduling_input: self.scheduling_input.unwrap_or_default(),
        })
    }
}

/// The unit of a local-model form as stored, and how a file's units become the model's.
trait UnitDoc: Sized {
    /// The local models of `units` (`structure` tells the two ARX forms apart).
    fn local(
        units: Vec<Self>,
        structure: Structure,
        zero_offsets: bool,
        reference_unit: Option<usize>,
    ) -> Result<LocalModelSet, FileError>;
}

/// One state-space unit struct per form, with its writer (`new`) and reader (`into_unit`):
/// the forms differ only in their matrices' fields (stored name = model name, in file
/// order); `dx` and `dy` follow them, omitted together with `zero_offsets`. With `local`,
/// also the [`UnitDoc`] that puts the units in that variant of [`LocalModelSet`].
macro_rules! ss_unit_doc {
    (
        $(#[$meta:meta])*
        $doc:ident for $unit:ident { $($field:ident: $stored:ty = $model:ident),* $(,)? }
        $(local: $variant:ident)?
    ) => {
        $(#[$meta])*
        #[derive(Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct $doc {
            $($field: $stored,)*
            #[serde(default, deserialize_with = "present")]
            #[serde(skip_serializing_if = "Option::is_none")]
            dx: Option<Pair<Num>>,
            #[serde(default, deserialize_with = "present")]
            #[serde(skip_serializing_if = "Option::is_none")]
            dy: Option<Num>,
        }

        impl $doc {
            fn new(m: &$unit<f64>, zero_offsets: bool) -> Self {
                let (dx, dy) = offsets_out(zero_offsets, m.dx, m.dy);
                Self {
                    $($field: <$stored>::of(m.$model),)*
                    dx,
                    dy,
                }
            }

            fn into_unit(self, i: usize, zero_offsets: bool) -> Result<$unit<f64>, FileError> {
                let (dx, dy) = offsets_in(i, zero_offsets, self.dx, self.dy)?;
                Ok($unit {
                    $($model: self.$field.get(),)*
                    dx,
                    dy,
                })
            }
        }

        $(
            impl UnitDoc for $doc {
                fn local(
                    units: Vec<Self>,
                    _: Structure,
                    zero_offsets: bool,
                    _: Option<usize>,
                ) -> Result<LocalModelSet, FileError> {
                    let units = each(units, |i, u| u.into_unit(i, zero_offsets))?;
                    Ok(LocalModelSet::$variant(units))
                }
            }
        )?
    };
}

ss_unit_doc! {
    /// An `ss-direct` unit.
    SsDirectDoc for SsLocalModel {
        a: Pair<Pair<Num>> = a,
        b: Pair<Num> = b,
        c: Pair<Num> = c,
    }
    local: SsDirect
}

ss_unit_doc! {
    /// An `ss-eig-local` unit.
    EigLocalDoc for EigLocalUnit {
        eigenvalues: Pair<Num> = eigenvalues,
        eigenvector_angles_rad: Pair<Num> = eigenvector_angles,
        b: Pair<Num> = b,
        c: Pair<Num> = c,
    }
    local: SsEigLocal
}

ss_unit_doc! {
    /// An `ss-eig-common` unit (modal coordinates).
    EigCommonDoc for EigCommonUnit {
        eigenvalues: Pair<Num> = eigenvalues,
        b: Pair<Num> = b,
        c: Pair<Num> = c,
    }
}

impl UnitDoc for EigCommonDoc {
    /// The units with their `reference_unit` (required for this form).
    fn local(
        units: Vec<Self>,
        _: Structure,
        zero_offsets: bool,
        reference_unit: Option<usize>,
    ) -> Result<LocalModelSet, FileError> {
        let reference_unit =
            reference_unit.ok_or_else(|| bad("(file)", "missing field `reference_unit`"))?;
        let units = each(units, |i, u| u.into_unit(i, zero_offsets))?;
        Ok(LocalModelSet::SsEigCommon {
            units,
            reference_unit,
        })
    }
}

/// An `arx-shift` or `arx-delta` unit: `a` and `b` have n entries each (the order).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ArxDoc {
    a: Vec<Num>,
    b: Vec<Num>,
    #[serde(default, deserialize_with = "present")]
    #[serde(skip_serializing_if = "Option::is_none")]
    d: Option<Num>,
}

impl ArxDoc {
    fn new(m: &ArxUnit<f64>, order: usize, zero_offsets: bool) -> Self {
        let first = |x: &[f64]| x.iter().take(order).map(|v| Num(*v)).collect();
        Self {
            a: first(&m.a),
            b: first(&m.b),
            d: (!zero_offsets).then_some(Num(m.d)),
        }
    }

    fn into_unit(self, i: usize, n: usize, zero_offsets: bool) -> Result<ArxUnit<f64>, FileError> {
        let mut m = ArxUnit::zero();
        for (name, from, to) in [("a", &self.a, &mut m.a), ("b", &self.b, &mut m.b)] {
            if from.len() != n {
                return Err(bad(
                    format!("units[{i}].{name}"),
                    format!("expected {n} numbers, found {}", from.len()),
                ));
            }
            for (t, f) in to.iter_mut().zip(from) {
                *t = f.0;
            }
        }
        m.d = match self.d {
            Some(d) => d.0,
            None if zero_offsets => 0.0,
            None => return Err(missing(i, "d")),
        };
        Ok(m)
    }
}

impl UnitDoc for ArxDoc {
    /// Units of either ARX form. The order n is the length of the first unit's `a`, in
    /// 1..=[`MAX_ARX_ORDER`].
    fn local(
        units: Vec<Self>,
        structure: Structure,
        zero_offsets: bool,
        _: Option<usize>,
    ) -> Result<LocalModelSet, FileError> {
        let first = units.first().ok_or_else(|| bad("units", "no units"))?;
        let order = first.a.len();
        if !(1..=MAX_ARX_ORDER).contains(&order) {
            return Err(bad(
                "units[0].a",
                format!("ARX order (length of a) {order} is outside 1..={MAX_ARX_ORDER}"),
            ));
        }
        let units = each(units, |i, u| u.into_unit(i, order, zero_offsets))?;
        Ok(if structure == Structure::ArxDelta {
            LocalModelSet::ArxDelta { order, units }
        } else {
            LocalModelSet::ArxShift { order, units }
        })
    }
}

/// Converts every unit, passing its index for the error's path.
fn each<U, M>(
    units: Vec<U>,
    convert: impl Fn(usize, U) -> Result<M, FileError>,
) -> Result<Vec<M>, FileError> {
    units
        .into_iter()
        .enumerate()
        .map(|(i, u)| convert(i, u))
        .collect()
}

/// A state-space unit's `dx` and `dy` as written: omitted with `zero_offsets`.
fn offsets_out(zero_offsets: bool, dx: [f64; 2], dy: f64) -> (Option<Pair<Num>>, Option<Num>) {
    if zero_offsets {
        (None, None)
    } else {
        (Some(Pair::<Num>::of(dx)), Some(Num(dy)))
    }
}

/// A state-space unit's `dx` and `dy` as read: both given, or both omitted with
/// `zero_offsets` (then zero).
fn offsets_in(
    i: usize,
    zero_offsets: bool,
    dx: Option<Pair<Num>>,
    dy: Option<Num>,
) -> Result<([f64; 2], f64), FileError> {
    match (dx, dy) {
        (Some(dx), Some(dy)) => Ok((dx.get(), dy.0)),
        (None, None) if zero_offsets => Ok(([0.0; 2], 0.0)),
        (None, _) => Err(missing(i, "dx")),
        (Some(_), None) => Err(missing(i, "dy")),
    }
}

/// A field of unit `i` that is missing (worded as serde words the others).
fn missing(i: usize, name: &str) -> FileError {
    bad(format!("units[{i}]"), format!("missing field `{name}`"))
}

/// A field that may be omitted but, when present, must hold a value (not null): used with
/// `#[serde(default, deserialize_with = "present")]` on an `Option`.
fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// Two entries: a vector of the state space (`Pair<Num>`) or the rows of `a`. Its reader
/// counts every entry, so that an error says "expected 2 numbers, found 3" (serde's own
/// reader of `[T; 2]` says only "expected fewer elements in array"); written as an array.
#[derive(Serialize)]
#[serde(transparent)]
struct Pair<T>([T; 2]);

impl Pair<Num> {
    fn of(x: [f64; 2]) -> Self {
        Self(x.map(Num))
    }

    fn get(self) -> [f64; 2] {
        self.0.map(|v| v.0)
    }
}

impl Pair<Pair<Num>> {
    fn of(x: [[f64; 2]; 2]) -> Self {
        Self(x.map(Pair::<Num>::of))
    }

    fn get(self) -> [[f64; 2]; 2] {
        self.0.map(Pair::<Num>::get)
    }
}

/// What the entries of a [`Pair`] are called in an error.
trait Entries {
    const NAME: &'static str;
}

impl Entries for Num {
    const NAME: &'static str = "numbers";
}

impl Entries for Pair<Num> {
    const NAME: &'static str = "rows";
}

impl<'de, T: Deserialize<'de> + Entries> Deserialize<'de> for Pair<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_seq(PairVisitor(PhantomData))
    }
}

struct PairVisitor<T>(PhantomData<T>);

impl<'de, T: Deserialize<'de> + Entries> Visitor<'de> for PairVisitor<T> {
    type Value = Pair<T>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "an array of 2 {}", T::NAME)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Pair<T>, A::Error> {
        let first = seq.next_element::<T>()?;
        let second = match first {
            Some(_) => seq.next_element::<T>()?,
            None => None,
        };
        let mut found = usize::from(first.is_some()) + usize::from(second.is_some());
        while seq.next_element::<IgnoredAny>()?.is_some() {
            found += 1;
        }
        match (first, second) {
            (Some(a), Some(b)) if found == 2 => Ok(Pair([a, b])),
            _ => Err(de::Error::custom(format_args!(
                "expected 2 {}, found {found}",
                T::NAME
            ))),
        }
    }
}

/// A number of the file. Read by its own visitor so that an error says "expected a finite
/// number" and explains a null (serde_json writes NaN as null); written as a plain f64.
#[derive(Serialize)]
#[serde(transparent)]
struct Num(f64);

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumVisitor)
    }
}

struct NumVisitor;

impl Visitor<'_> for NumVisitor {
    type Value = Num;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a finite number")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Num, E> {
        if v.is_finite() {
            Ok(Num(v))
        } else {
            Err(E::invalid_value(Unexpected::Float(v), &self))
        }
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Num, E> {
        Ok(Num(v as f64))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Num, E> {
        Ok(Num(v as f64))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Num, E> {
        Err(E::custom(
            "invalid type: null, expected a finite number (NaN or a missing value?)",
        ))
    }
}

/// A count of the file (`delay_samples`, `order`, `reference_unit`); an error says
/// "expected a non-negative integer".
#[derive(Serialize)]
#[serde(transparent)]
struct Count(usize);

impl<'de> Deserialize<'de> for Count {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_u64(CountVisitor)
    }
}

struct CountVisitor;

impl Visitor<'_> for CountVisitor {
    type Value = Count;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a non-negative integer")
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Count, E> {
        usize::try_from(v)
            .map(Count)
            .map_err(|_| E::invalid_value(Unexpected::Unsigned(v), &self))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Count, E> {
        match u64::try_from(v) {
            Ok(v) => self.visit_u64(v),
            Err(_) => Err(E::invalid_value(Unexpected::Signed(v), &self)),
        }
    }
}
