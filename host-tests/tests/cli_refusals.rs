//! Inputs the tool used to take without a word, now refused with a message
//! that names what is wrong; and help texts that speak to the user, not
//! to the project's issue tracker.

use assert_cmd::cargo::cargo_bin_cmd;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn stdout_of(args: &[&str]) -> String {
    let out = ct().args(args).output().unwrap();
    assert!(out.status.success(), "coil-thermal {args:?} failed");
    String::from_utf8(out.stdout).unwrap()
}

/// Where `text` names an issue by number (`issue 17`, `Issue 20`).
fn issue_numbers(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    lower
        .match_indices("issue ")
        .filter(|(k, m)| {
            lower[k + m.len()..]
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        })
        .map(|(k, _)| lower[k..].chars().take(40).collect())
        .collect()
}

#[test]
fn issue_numbers_are_found_by_the_help_check() {
    // The check itself: it must see what it is meant to refuse.
    assert_eq!(issue_numbers("Issue 17's fault campaign").len(), 1);
    assert_eq!(issue_numbers("see issue 3").len(), 1);
    assert!(issue_numbers("the issue's goals, issues galore").is_empty());
}

/// `--help` of the tool and of every subcommand it lists names no issue
/// number: a user has no access to the project's tracker.
#[test]
fn no_help_text_names_an_issue_number() {
    let top = stdout_of(&["--help"]);
    let mut found = issue_numbers(&top);
    let commands: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter(|l| l.starts_with("  ") && !l[2..].starts_with(' '))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    for expected in [
        "simulate",
        "replay",
        "limits",
        "calibrate",
        "codegen",
        "faults",
    ] {
        assert!(
            commands.contains(&expected),
            "`{expected}` is not among the commands --help lists: {commands:?}"
        );
    }
    for c in &commands {
        for text in [stdout_of(&[c, "--help"]), stdout_of(&[c, "-h"])] {
            found.extend(
                issue_numbers(&text)
                    .into_iter()
                    .map(|m| format!("{c}: {m}")),
            );
        }
    }
    assert!(found.is_empty(), "help texts name issues: {found:#?}");
}
