//! Every command line of the README, run as written, in order, so that the README cannot
//! drift from the binary.
//!
//! The commands are the lines of the README's `sh` blocks (a trailing `\` joins the next
//! line). They run in a fresh folder laid out as a user's clone is, with `examples/` and
//! `../shared` beside it, through `bash` with the binary under test first on `PATH`: what
//! the quick start leaves. A command under a comment that says `[hardware]` needs a sensor
//! board or a sound card and is skipped; the quick start's own lines are this test itself
//! (its `cargo run -p underfoot-cli -- demo` runs as `underfoot demo`); `underfoot panel`
//! serves until Ctrl-C and is skipped with the line that installs it (the panel's tests
//! run it, in CI with the `panel` feature). Any other line that is
//! not an `underfoot` command fails the test: a new kind of line needs a rule here.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{bin, footsteps_dir};

/// One command line of the README.
#[derive(Debug, PartialEq)]
struct Line {
    /// The README's line number where the command starts.
    number: usize,
    /// The command, continuation lines joined.
    text: String,
    /// Under a `[hardware]` comment.
    hardware: bool,
}

/// The command lines of every `sh` block of `readme`.
fn command_lines(readme: &str) -> Vec<Line> {
    let mut lines = Vec::new();
    let mut in_sh = false;
    let mut hardware = false;
    let mut pending: Option<Line> = None;
    for (i, raw) in readme.lines().enumerate() {
        let number = i + 1;
        if raw.starts_with("```") {
            in_sh = !in_sh && raw.trim_end() == "```sh";
            hardware = false;
            continue;
        }
        if !in_sh {
            continue;
        }
        let (body, continues) = match raw.trim_end().strip_suffix('\\') {
            Some(body) => (body.trim_end(), true),
            None => (raw.trim_end(), false),
        };
        let line = match pending.take() {
            Some(mut line) => {
                line.text.push(' ');
                line.text.push_str(body.trim_start());
                line
            }
            None => {
                let body = body.trim_start();
                if body.starts_with('#') {
                    hardware |= body.contains("[hardware]");
                    continue;
                }
                if body.is_empty() {
                    hardware = false;
                    continue;
                }
                Line {
                    number,
                    text: body.to_owned(),
                    hardware: std::mem::take(&mut hardware),
                }
            }
        };
        if continues {
            pending = Some(line);
        } else {
            lines.push(line);
        }
    }
    lines.extend(pending);
    lines
}

/// What the test does with a line.
#[derive(Debug, PartialEq)]
enum Action {
    /// Run it with `bash -c`.
    Run(String),
    /// The quick start's lines that this test stands for.
    Skip(&'static str),
    /// A Python example: run when `python3` with numpy is there (CI makes it so,
    /// `UNDERFOOT_REQUIRE_PYTHON`), else skipped, saying so.
    Python(String),
}

fn action(line: &Line) -> Result<Action, String> {
    let text = line.text.as_str();
    if line.hardware {
        return Ok(Action::Skip("needs hardware"));
    }
    if let Some(args) = text.strip_prefix("cargo run -p underfoot-cli -- ") {
        return Ok(Action::Run(format!("underfoot {args}")));
    }
    if text.starts_with("cargo test --workspace") {
        return Ok(Action::Skip("the test command that runs this test"));
    }
    if text == "cargo install --path crates/underfoot-cli --features panel" {
        return Ok(Action::Skip(
            "installs the panel's build; tests/cli/panel_*.rs test it",
        ));
    }
    if text == "pip install ./crates/underfoot-py" {
        return Ok(Action::Skip(
            "builds the Python package (minutes); .ci/run runs it in a new virtual \
             environment, then the package's pytest tests",
        ));
    }
    if text == "scripts/install-audio" {
        return Ok(Action::Skip(
            "installs system packages with apt-get; .ci/audio-setup does it in CI",
        ));
    }
    if text.starts_with("underfoot panel ") {
        return Ok(Action::Skip(
            "serves until Ctrl-C; tests/cli/panel_*.rs run it (CI, with the panel feature)",
        ));
    }
    if text == r#"export PATH="$PWD/target/debug:$PATH""# {
        return Ok(Action::Skip("this test puts the binary under test on PATH"));
    }
    if text == "underfoot" || text.starts_with("underfoot ") {
        return Ok(Action::Run(text.to_owned()));
    }
    // Markers piped into a recorded session.
    if text.starts_with("printf ") && text.contains("| underfoot ") {
        return Ok(Action::Run(text.to_owned()));
    }
    if text.starts_with("python3 examples/python/") {
        return Ok(Action::Python(text.to_owned()));
    }
    Err(format!(
        "README.md:{}: the README-commands test does not know how to run `{text}`: \
         mark it `# [hardware]` or teach tests/cli/readme.rs",
        line.number
    ))
}

#[test]
fn the_readme_parser_joins_continuations_and_marks_hardware() {
    let readme = "text\n```sh\n# a comment\nunderfoot a \\\n    --b c\n# [hardware] a board\n\
                  underfoot d\nunderfoot e  # trailing\n```\n```toml\nunderfoot f\n```\n";
    let lines = command_lines(readme);
    assert_eq!(
        lines,
        vec![
            Line {
                number: 4,
                text: "underfoot a --b c".into(),
                hardware: false
            },
            Line {
                number: 7,
                text: "underfoot d".into(),
                hardware: true
            },
            Line {
                number: 8,
                text: "underfoot e  # trailing".into(),
                hardware: false
            },
        ]
    );
    assert_eq!(action(&lines[1]), Ok(Action::Skip("needs hardware")));
    let unknown = Line {
        number: 9,
        text: "make install".into(),
        hardware: false,
    };
    assert!(action(&unknown).unwrap_err().contains("README.md:9"));
}

/// Whether `python3` with numpy runs here; with `UNDERFOOT_REQUIRE_PYTHON` set (CI), it
/// must.
fn python_with_numpy() -> bool {
    let there = Command::new("python3")
        .args(["-c", "import numpy"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        there || std::env::var_os("UNDERFOOT_REQUIRE_PYTHON").is_none(),
        "UNDERFOOT_REQUIRE_PYTHON is set, and python3 with numpy does not run"
    );
    there
}

/// The longest any one README command may take (the longest, `run` of an 8-step walk paced
/// in real time, takes about 10 s).
const COMMAND_TIMEOUT: Duration = Duration::from_secs(120);

/// A user's clone in a fresh folder: `proj/examples` and `shared` are links to the real
/// ones, so the README's relative paths (`examples/...`, `../shared/data/...`) resolve.
fn user_clone(root: &Path, footsteps: &Path) -> PathBuf {
    let project = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let shared = footsteps.join("../..");
    let proj = root.join("proj");
    std::fs::create_dir(&proj).expect("project folder");
    std::os::unix::fs::symlink(project.join("examples"), proj.join("examples"))
        .expect("link examples");
    std::os::unix::fs::symlink(shared, root.join("shared")).expect("link shared");
    proj
}

#[test]
#[ignore = "slow tier: every README command, with real recordings and real-time runs (~55 s)"]
fn every_readme_command_runs_as_written() {
    let Some(footsteps) = footsteps_dir() else {
        return;
    };
    let readme_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../README.md");
    let readme = std::fs::read_to_string(&readme_path).expect("README.md");
    let lines = command_lines(&readme);
    let actions: Vec<(Line, Action)> = lines
        .into_iter()
        .map(|line| {
            let action = action(&line).unwrap_or_else(|e| panic!("{e}"));
            (line, action)
        })
        .collect();
    let runs = actions
        .iter()
        .filter(|(_, a)| matches!(a, Action::Run(_)))
        .count();
    assert!(runs >= 20, "only {runs} README commands found to run");

    let root = tempfile::tempdir().expect("temp dir");
    let proj = user_clone(root.path(), &footsteps);
    let bin_dir = bin().parent().expect("binary's folder").to_path_buf();
    let path = std::env::join_paths(std::iter::once(bin_dir).chain(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    )))
    .expect("PATH");

    for (line, action) in &actions {
        let command = match action {
            Action::Skip(why) => {
                eprintln!("README.md:{}: skipped ({why}): {}", line.number, line.text);
                continue;
            }
            Action::Run(command) => command,
            Action::Python(command) => {
                if python_with_numpy() {
                    command
                } else {
                    eprintln!(
                        "README.md:{}: skipped (no python3 with numpy here): {}",
                        line.number, line.text
                    );
                    continue;
                }
            }
        };
        // Files, not pipes: a command that prints more than a pipe holds would block while
        // this loop only polls it.
        let out_path = root.path().join("stdout");
        let err_path = root.path().join("stderr");
        let started = Instant::now();
        let mut child = Command::new("bash")
            .arg("-c")
            .arg(command)
            .current_dir(&proj)
            .env("PATH", &path)
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&out_path).expect("stdout file"))
            .stderr(std::fs::File::create(&err_path).expect("stderr file"))
            .spawn()
            .expect("spawn bash");
        let status = loop {
            if let Some(status) = child.try_wait().expect("wait") {
                break status;
            }
            if started.elapsed() > COMMAND_TIMEOUT {
                child.kill().ok();
                child.wait().ok();
                panic!(
                    "README.md:{}: `{}` still running after {COMMAND_TIMEOUT:?}",
                    line.number, line.text
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        assert!(
            status.success(),
            "README.md:{}: `{}` failed ({status})\nstdout:\n{}\nstderr:\n{}",
            line.number,
            line.text,
            std::fs::read_to_string(&out_path).unwrap_or_default(),
            std::fs::read_to_string(&err_path).unwrap_or_default()
        );
        eprintln!(
            "README.md:{}: ok in {:.1} s: {}",
            line.number,
            started.elapsed().as_secs_f64(),
            line.text
        );
    }
}
