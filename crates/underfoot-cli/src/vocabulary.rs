//! One word for one thing: the flags renamed so that no name means two things in two
//! commands, and the old spellings, which keep working for one release with a warning
//! that names the new one.
//!
//! The old spellings are rewritten before clap sees the command line, by subcommand, so
//! that `--rate` still reaches `fit`'s analysis rate and `render`'s audio rate alike, and
//! a flag that now means something else is never taken for it. A test walks every
//! subcommand's definition: each renamed flag exists under its new name and not under its
//! old one, and no long flag means two things (its help's first line is the same
//! wherever it appears, but for the few listed in the test with why).

use std::ffi::OsString;

/// A flag renamed in the commands `commands` (each a subcommand path, `calibrate sweep`).
pub struct Renamed {
    pub commands: &'static [&'static str],
    pub old: &'static str,
    pub new: &'static str,
}

const LIVE: &[&str] = &["run", "panel", "render", "demo"];
const CALIBRATE: &[&str] = &["calibrate sweep", "calibrate equalize"];

/// Every renamed flag (without the leading `--`).
pub const RENAMED: &[Renamed] = &[
    // fit: the material's name, the library it goes into, and the analysis rate, which
    // is not the audio rate `--rate` meant elsewhere.
    Renamed {
        commands: &["fit"],
        old: "material",
        new: "name",
    },
    Renamed {
        commands: &["fit"],
        old: "out",
        new: "library",
    },
    Renamed {
        commands: &["fit"],
        old: "rate",
        new: "analysis-rate",
    },
    // The audio rate: one name wherever a sound card's rate is meant.
    Renamed {
        commands: LIVE,
        old: "rate",
        new: "audio-rate",
    },
    Renamed {
        commands: CALIBRATE,
        old: "rate",
        new: "audio-rate",
    },
    // calibrate: one sweep's length is not a session's; the device under test is not
    // the output device; the simulated noise's seed is not the perturbation's.
    Renamed {
        commands: CALIBRATE,
        old: "duration",
        new: "sweep-duration",
    },
    Renamed {
        commands: CALIBRATE,
        old: "device",
        new: "device-under-test",
    },
    Renamed {
        commands: CALIBRATE,
        old: "seed",
        new: "noise-seed",
    },
    // render writes a sample format; export's `--format` is the header's.
    Renamed {
        commands: &["render"],
        old: "format",
        new: "sample-format",
    },
    // compare: a folder of plots and a JSON file, where `--plot` and `--json` are a file
    // and a switch elsewhere.
    Renamed {
        commands: &["compare"],
        old: "plot",
        new: "plot-dir",
    },
    Renamed {
        commands: &["compare"],
        old: "json",
        new: "json-out",
    },
];

/// The subcommand path of `args` (after the program's name) in `cli`: `fit`,
/// `calibrate sweep` (a word names a subcommand of the one before it for as long as
/// `cli` has one of that name).
fn command_of(cli: &clap::Command, args: &[OsString]) -> String {
    let mut path: Vec<&str> = Vec::new();
    let mut at = cli;
    for word in args.iter().skip(1).map_while(|a| a.to_str()) {
        let Some(sub) = at.find_subcommand(word) else {
            break;
        };
        path.push(word);
        at = sub;
    }
    path.join(" ")
}

/// `args` with every old spelling of its command's renamed flags (the command found in
/// `cli`) replaced by the new one (`--old` and `--old=VALUE`; nothing after `--`), and a
/// warning for each.
pub fn modernise(cli: &clap::Command, mut args: Vec<OsString>) -> (Vec<OsString>, Vec<String>) {
    let command = command_of(cli, &args);
    let mut warnings = Vec::new();
    for arg in args.iter_mut().skip(1) {
        let Some(text) = arg.to_str() else { continue };
        if text == "--" {
            break;
        }
        let Some(flag) = text.strip_prefix("--") else {
            continue;
        };
        let (name, value) = match flag.split_once('=') {
            Some((name, value)) => (name, Some(value)),
            None => (flag, None),
        };
        let Some(r) = RENAMED
            .iter()
            .find(|r| r.old == name && r.commands.contains(&command.as_str()))
        else {
            continue;
        };
        warnings.push(format!(
            "underfoot: warning: `{command} --{}` is now `--{}`; the old spelling goes in the \
             next release",
            r.old, r.new
        ));
        *arg = match value {
            Some(v) => format!("--{}={v}", r.new).into(),
            None => format!("--{}", r.new).into(),
        };
    }
    (args, warnings)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn os(args: &[&str]) -> Vec<OsString> {
        args.iter().map(OsString::from).collect()
    }

    #[test]
    fn old_spellings_reach_their_new_flag_in_their_command_only() {
        let (args, warnings) = modernise(
            &crate::command_line(),
            os(&[
                "underfoot",
                "fit",
                "--material",
                "m",
                "--rate=4000",
                "x.wav",
            ]),
        );
        assert_eq!(
            args,
            os(&[
                "underfoot",
                "fit",
                "--name",
                "m",
                "--analysis-rate=4000",
                "x.wav"
            ])
        );
        assert_eq!(warnings.len(), 2);
        assert!(
            warnings[1].contains("`fit --rate` is now `--analysis-rate`"),
            "{warnings:?}"
        );
        let (args, _) = modernise(
            &crate::command_line(),
            os(&[
                "underfoot",
                "render",
                "--rate",
                "44100",
                "--material",
                "sand",
            ]),
        );
        assert_eq!(
            args,
            os(&[
                "underfoot",
                "render",
                "--audio-rate",
                "44100",
                "--material",
                "sand"
            ])
        );
        let (args, _) = modernise(
            &crate::command_line(),
            os(&["underfoot", "calibrate", "sweep", "--device", "simulated"]),
        );
        assert_eq!(args[3], "--device-under-test");
        // Nothing after `--`, and nothing of another command.
        let (args, warnings) = modernise(
            &crate::command_line(),
            os(&["underfoot", "export", "--format", "c", "--", "--rate"]),
        );
        assert_eq!(
            args,
            os(&["underfoot", "export", "--format", "c", "--", "--rate"])
        );
        assert!(warnings.is_empty());
    }

    /// Calls `visit(command, argument)` for every argument of every subcommand, the
    /// command named by its path (`calibrate sweep`; empty for the top level).
    fn each_argument(visit: &mut dyn FnMut(&str, &clap::Arg)) {
        fn walk(c: &clap::Command, path: &str, visit: &mut dyn FnMut(&str, &clap::Arg)) {
            for a in c.get_arguments() {
                visit(path, a);
            }
            for s in c.get_subcommands() {
                let sub = if path.is_empty() {
                    s.get_name().to_owned()
                } else {
                    format!("{path} {}", s.get_name())
                };
                walk(s, &sub, visit);
            }
        }
        walk(&crate::command_line(), "", visit);
    }

    /// Every long flag of every subcommand: (flag, command) -> first line of its help.
    fn flags() -> BTreeMap<String, Vec<(String, String)>> {
        let mut out: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
        each_argument(&mut |path, a| {
            if let Some(long) = a.get_long() {
                let help = a.get_help().map(ToString::to_string).unwrap_or_default();
                let first = help.lines().next().unwrap_or("").to_owned();
                out.entry(long.to_owned())
                    .or_default()
                    .push((path.to_owned(), first));
            }
        });
        out
    }

    #[test]
    fn every_renamed_flag_is_there_under_its_new_name_only() {
        let flags = flags();
        for r in RENAMED {
            for command in r.commands {
                let has = |name: &str| {
                    flags
                        .get(name)
                        .is_some_and(|uses| uses.iter().any(|(c, _)| c == command))
                };
                assert!(has(r.new), "`{command}` has no --{}", r.new);
                assert!(!has(r.old), "`{command}` still defines --{}", r.old);
            }
        }
    }

    /// No long flag means two things: wherever it appears, its help's first line is the
    /// same, but for these, whose lines differ by what the command does with one thing.
    #[test]
    fn no_flag_means_two_things() {
        const SAME_THING: &[(&str, &str)] = &[
            (
                "band",
                "a band of frequencies in Hz: the one fitted or the one measured",
            ),
            (
                "buffer",
                "frames per audio buffer, for the live output or the sweep's device",
            ),
            (
                "device-under-test",
                "the device measured: simulated, a measured file, or a sound card",
            ),
            (
                "eq",
                "an equalizer file from `calibrate equalize`, applied or measured through",
            ),
            ("gait", "a generated walk's spec"),
            ("host", "the audio host"),
            ("json", "print JSON instead of text"),
            ("library", "a library file, read or edited"),
            ("material", "the material of each channel"),
            (
                "name",
                "the name of the entry added to the file: a material, a user",
            ),
            ("out", "the file this command writes"),
            ("plot", "the figure this command draws, one file"),
            ("steps", "the heel strikes of a generated walk per material"),
            ("user", "a user's limb model"),
            ("help", "clap's"),
            ("version", "clap's"),
        ];
        let mut clashes = Vec::new();
        for (flag, uses) in flags() {
            let mut lines: Vec<&str> = uses.iter().map(|(_, h)| h.as_str()).collect();
            lines.sort_unstable();
            lines.dedup();
            if lines.len() > 1 && !SAME_THING.iter().any(|(f, _)| *f == flag) {
                clashes.push(format!("--{flag}: {uses:?}"));
            }
        }
        assert!(
            clashes.is_empty(),
            "one name, two meanings:\n{}",
            clashes.join("\n")
        );
    }

    /// Every option that takes a value and may be left out says what happens then: a
    /// default clap shows, or its help says "default" (or what leaving it out means).
    #[test]
    fn every_option_states_its_default() {
        let mut missing = Vec::new();
        each_argument(&mut |path, a| {
            let takes_value = a.get_action().takes_values();
            if !takes_value
                || a.is_required_set()
                || a.is_positional()
                || !a.get_default_values().is_empty()
            {
                return;
            }
            let help = [a.get_help(), a.get_long_help()]
                .into_iter()
                .flatten()
                .map(|h| h.to_string().to_lowercase())
                .collect::<Vec<_>>()
                .join(" ");
            if !(help.contains("default") || help.contains("without it")) {
                missing.push(format!(
                    "`{path}` --{}: {}",
                    a.get_long().unwrap_or("?"),
                    help.lines().next().unwrap_or("")
                ));
            }
        });
        assert!(
            missing.is_empty(),
            "{} options do not say what leaving them out does:\n{}",
            missing.len(),
            missing.join("\n")
        );
    }
}
