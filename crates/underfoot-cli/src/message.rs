//! Error messages a person can read: what the user typed is echoed back, but not all of a
//! 100 kB argument.

use std::borrow::Cow;

/// The longest word (a run of non-whitespace: a path, a spec, a material name) an error
/// message echoes in full.
pub const MAX_ECHOED: usize = 160;

/// An error and its causes on one line, "what we did: why it failed", each cause said
/// once: many of the library's errors already end with their source (`"{path}: {source}"`,
/// as a person reading one error alone needs), and anyhow's `{:#}` then repeated it
/// ("No space left on device (os error 28): No space left on device (os error 28)"). A
/// cause whose text the line already holds is left out.
pub fn chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for link in e.chain() {
        let text = link.to_string();
        if text.is_empty() || out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// `message` with every word longer than [`MAX_ECHOED`] characters cut to its start and
/// end, saying how long it was: `aaaa…aaaa (100000 characters)`. Shorter words, and the
/// message's layout (newlines, indentation), are kept as they were.
pub fn shorten(message: &str) -> Cow<'_, str> {
    if !message
        .split(char::is_whitespace)
        .any(|w| w.chars().count() > MAX_ECHOED)
    {
        return Cow::Borrowed(message);
    }
    let mut out = String::with_capacity(message.len().min(64 * 1024));
    let mut word = String::new();
    let flush = |word: &mut String, out: &mut String| {
        let n = word.chars().count();
        if n > MAX_ECHOED {
            let keep = MAX_ECHOED / 2 - 8;
            let head: String = word.chars().take(keep).collect();
            let tail: String = word.chars().skip(n - keep).collect();
            out.push_str(&format!("{head}…{tail} ({n} characters)"));
        } else {
            out.push_str(word);
        }
        word.clear();
    };
    for c in message.chars() {
        if c.is_whitespace() {
            flush(&mut word, &mut out);
            out.push(c);
        } else {
            word.push(c);
        }
    }
    flush(&mut word, &mut out);
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cause_already_said_is_not_repeated() {
        // As the library's errors are: the source in the message and as the source.
        #[derive(Debug)]
        struct Write {
            path: String,
            source: std::io::Error,
        }
        impl std::fmt::Display for Write {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "{}: {}", self.path, self.source)
            }
        }
        impl std::error::Error for Write {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.source)
            }
        }
        let disk = std::io::Error::from_raw_os_error(28);
        let said = disk.to_string();
        let e = anyhow::Error::new(Write {
            path: "x.wav".into(),
            source: disk,
        })
        .context("rendering");
        let line = chain(&e);
        assert_eq!(line, format!("rendering: x.wav: {said}"));
        // A cause the line does not hold yet is kept.
        let e = anyhow::anyhow!("the cause").context("what we did");
        assert_eq!(chain(&e), "what we did: the cause");
    }

    #[test]
    fn long_words_are_cut_and_the_rest_kept() {
        let long = "x".repeat(100_000);
        let msg = format!("error: no material \"{long}\" in the library\n  tip: list them");
        let got = shorten(&msg);
        assert!(got.len() < 300, "{}", got.len());
        assert!(got.contains("(100002 characters)"), "{got}");
        assert!(got.starts_with("error: no material \"xxx"));
        assert!(
            got.ends_with("xx\" (100002 characters) in the library\n  tip: list them"),
            "{got}"
        );
        let short = "reading /tmp/a.csv: No such file";
        assert!(matches!(shorten(short), Cow::Borrowed(s) if s == short));
        // Multi-byte characters are counted as characters, never split.
        let wide = "é".repeat(MAX_ECHOED + 1);
        assert!(shorten(&wide).contains(&format!("({} characters)", MAX_ECHOED + 1)));
    }
}
