//! POSIX shell quoting for the guest's init script.

/// `s` as one single-quoted shell word (`'` becomes `'\''`).
pub(crate) fn quote(s: &str) -> String {
    let mut q = String::with_capacity(s.len() + 2);
    q.push('\'');
    for c in s.chars() {
        if c == '\'' {
            q.push_str("'\\''");
        } else {
            q.push(c);
        }
    }
    q.push('\'');
    q
}

/// True when `name` can be exported by a POSIX shell (`[A-Za-z_][A-Za-z0-9_]*`).
pub(crate) fn is_env_name(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c == '_' || c.is_ascii_alphabetic())
        && chars.all(|c| c == '_' || c.is_ascii_alphanumeric())
}

/// `export NAME='value'` lines for every valid name.
pub(crate) fn exports<'a>(vars: impl IntoIterator<Item = (&'a str, &'a str)>) -> String {
    let mut out = String::new();
    for (k, v) in vars {
        if is_env_name(k) && !v.contains('\0') {
            out.push_str("export ");
            out.push_str(k);
            out.push('=');
            out.push_str(&quote(v));
            out.push('\n');
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    /// The quoted word, read back by a real shell, is the original string.
    #[test]
    fn quoting_round_trips_through_sh() {
        for s in [
            "plain",
            "with space",
            "it's",
            "'",
            "$HOME `x` \"q\" \\ ;|&",
            "line\nbreak",
            "",
        ] {
            let out = Command::new("sh")
                .arg("-c")
                .arg(format!("printf %s {}", quote(s)))
                .output()
                .unwrap();
            assert_eq!(String::from_utf8(out.stdout).unwrap(), s);
        }
    }

    #[test]
    fn env_names() {
        assert!(is_env_name("CAN_IFACE"));
        assert!(is_env_name("_x1"));
        assert!(!is_env_name("1x"));
        assert!(!is_env_name("BASH_FUNC_f%%"));
        assert!(!is_env_name(""));
        let e = exports([("A", "it's"), ("bad-name", "x")]);
        assert_eq!(e, "export A='it'\\''s'\n");
    }
}
