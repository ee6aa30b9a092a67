//! Versioned TOML configuration files of the real-time processes (rt-core's
//! `fes-rt-core/1`, stim-driver's `fes-stim-driver/1`): read once at start-up, parsed into a
//! serde type that denies unknown keys, checked for its `schema` tag and every value's
//! range. One implementation of the reading ([`load`]), the errors, the range check and
//! the resolution of the paths a file names ([`resolve`]); each process wraps
//! [`FileError`] in its own error type, next to its own checks.

use std::borrow::Cow;
use std::fmt;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// What is wrong with a configuration file, naming the file or the key.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not valid TOML for this schema (unknown key, wrong type, missing table...).
    #[error("{path}: {source}")]
    Parse {
        /// The file (empty for text parsed without a file).
        path: PathBuf,
        /// The cause (with line and column).
        source: Box<toml::de::Error>,
    },
    /// Wrong `schema`.
    #[error("schema is {found:?}, expected {expected:?}")]
    Schema {
        /// What the file says.
        found: String,
        /// What this version reads.
        expected: &'static str,
    },
    /// A value is out of range.
    #[error("{field} = {value} is out of range ({allowed})")]
    Range {
        /// Dotted key.
        field: &'static str,
        /// The value.
        value: String,
        /// What is allowed.
        allowed: Cow<'static, str>,
    },
}

impl FileError {
    /// The error as found in the file `path` (a parse error of text names no file).
    pub fn in_file(self, path: &Path) -> Self {
        match self {
            FileError::Parse { source, .. } => FileError::Parse {
                path: path.to_path_buf(),
                source,
            },
            other => other,
        }
    }
}

/// The text of the file `path`.
pub fn read(path: &Path) -> Result<String, FileError> {
    std::fs::read_to_string(path).map_err(|source| FileError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads the file `path` and parses it into `T` (no validation beyond the shape); a parse
/// error names the file. The processes check the values after, with [`range`].
pub fn load<T: DeserializeOwned>(path: &Path) -> Result<T, FileError> {
    parse(&read(path)?).map_err(|e| e.in_file(path))
}

/// Makes `p`, a path written in the file `file`, absolute: a relative one is relative to
/// the file's directory (so the configuration means the same from any working directory).
pub fn resolve(file: &Path, p: &mut PathBuf) {
    if p.is_relative() {
        let joined = file.parent().unwrap_or(Path::new("")).join(&*p);
        *p = std::path::absolute(&joined).unwrap_or(joined);
    }
}

/// Parses TOML `text` into `T` (no validation beyond the shape).
pub fn parse<T: DeserializeOwned>(text: &str) -> Result<T, FileError> {
    toml::from_str(text).map_err(|source| FileError::Parse {
        path: PathBuf::new(),
        source: Box::new(source),
    })
}

/// `Ok` when the file's `schema` tag is `expected`.
pub fn check_schema(found: &str, expected: &'static str) -> Result<(), FileError> {
    if found == expected {
        Ok(())
    } else {
        Err(FileError::Schema {
            found: found.to_owned(),
            expected,
        })
    }
}

/// `Ok` when `ok`; otherwise the range error of `field` holding `value`, with what is
/// `allowed`.
pub fn range<T: ToString>(
    ok: bool,
    field: &'static str,
    value: T,
    allowed: &'static str,
) -> Result<(), FileError> {
    if ok {
        Ok(())
    } else {
        Err(FileError::Range {
            field,
            value: value.to_string(),
            allowed: Cow::Borrowed(allowed),
        })
    }
}

/// `Ok` when `value` lies in `allowed`; otherwise the range error of `field`, naming the
/// range as `lo..=hi`, so the bounds are written once.
pub fn within<T: PartialOrd + fmt::Display>(
    field: &'static str,
    value: T,
    allowed: RangeInclusive<T>,
) -> Result<(), FileError> {
    if allowed.contains(&value) {
        Ok(())
    } else {
        Err(FileError::Range {
            field,
            value: value.to_string(),
            allowed: Cow::Owned(format!("{}..={}", allowed.start(), allowed.end())),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Small {
        schema: String,
        n: u32,
    }

    #[test]
    fn errors_name_the_file_the_key_and_what_is_allowed() {
        let e = read(Path::new("/nonexistent/x.toml")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("cannot read /nonexistent/x.toml: "),
            "{e}"
        );

        let e = parse::<Small>("schema = \"a/1\"\nn = 1\nm = 2\n").unwrap_err();
        let e = e.in_file(Path::new("/etc/fes/x.toml")).to_string();
        assert!(
            e.starts_with("/etc/fes/x.toml: ") && e.contains("unknown field `m`"),
            "{e}"
        );

        let ok: Small = parse("schema = \"a/1\"\nn = 1\n").unwrap();
        assert!(check_schema(&ok.schema, "a/1").is_ok());
        assert_eq!(
            check_schema(&ok.schema, "a/2").unwrap_err().to_string(),
            "schema is \"a/1\", expected \"a/2\""
        );
        assert!(range(ok.n >= 1, "n", ok.n, ">= 1").is_ok());
        assert_eq!(
            range(ok.n >= 2, "n", ok.n, ">= 2").unwrap_err().to_string(),
            "n = 1 is out of range (>= 2)"
        );
        // Not a parse error: unchanged by in_file.
        let r = range(false, "n", 0, ">= 1")
            .unwrap_err()
            .in_file(Path::new("/x"));
        assert!(matches!(r, FileError::Range { field: "n", .. }));
    }

    #[test]
    fn a_loaded_file_names_itself_in_parse_errors_and_its_relative_paths_resolve_against_it() {
        let dir = fes_testkit::Scratch::new("config-file");
        let path = dir.join("x.toml");
        std::fs::write(&path, "schema = \"a/1\"\nn = 3\n").unwrap();
        let ok: Small = load(&path).unwrap();
        assert_eq!((ok.schema.as_str(), ok.n), ("a/1", 3));
        std::fs::write(&path, "schema = \"a/1\"\nn = 3\nm = 2\n").unwrap();
        let e = load::<Small>(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: ", path.display())) && e.contains("unknown field `m`"),
            "{e}"
        );
        let e = load::<Small>(&dir.join("absent.toml")).unwrap_err();
        assert!(matches!(e, FileError::Read { .. }), "{e}");

        let mut p = PathBuf::from("sub/p.toml");
        resolve(&path, &mut p);
        assert_eq!(p, dir.join("sub/p.toml"));
        let mut abs = PathBuf::from("/etc/fes/p.toml");
        resolve(&path, &mut abs);
        assert_eq!(abs, PathBuf::from("/etc/fes/p.toml"));
        // A file named without a directory: its paths are relative to the working
        // directory, made absolute.
        let mut bare = PathBuf::from("p.toml");
        resolve(Path::new("x.toml"), &mut bare);
        assert_eq!(bare, std::env::current_dir().unwrap().join("p.toml"));
    }
}
