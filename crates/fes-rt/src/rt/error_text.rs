//! One-line error text for the processes' logs.

use std::error::Error;

/// The error and its causes on one line, `outer: cause: root`, skipping a cause whose text
/// the line already contains (many errors repeat their source in their own message).
pub fn one_line(error: &(dyn Error + 'static)) -> String {
    let mut line = error.to_string();
    let mut cause = error.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        cause = c.source();
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("reading {path}: {source}")]
    struct Repeats {
        path: &'static str,
        source: std::io::Error,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("configuration")]
    struct Outer(#[source] Repeats);

    #[test]
    fn causes_are_appended_once() {
        let e = Outer(Repeats {
            path: "a.toml",
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        });
        assert_eq!(one_line(&e), "configuration: reading a.toml: no such file");
    }
}
