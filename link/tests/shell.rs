//! `hopper-link shell --stop-on-error`: the first command that does not go
//! as written ends the session, and nothing after it reaches the robot (a
//! refused routine is never followed by `save`); without the flag the
//! session goes on and reports at the end.

mod common;

use hopper_protocol::vocab::Refusal;
use hopper_protocol::{Request, Response};
use std::io::Write;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A robot that refuses every routine (and answers what else a routine
/// asks first as no robot would: the command fails either way) and records
/// the requests that act.
fn session(flags: &[&str]) -> (bool, String, Vec<String>) {
    let acted = Arc::new(Mutex::new(Vec::new()));
    let seen = acted.clone();
    let (addr, robot) = common::robot(
        10,
        Duration::from_millis(5),
        move |req| {
            let name = match req {
                Request::Calibrate { .. } => Some("calibrate"),
                Request::Save => Some("save"),
                Request::Arm => Some("arm"),
                _ => None,
            };
            if let (Some(n), Ok(mut a)) = (name, seen.lock()) {
                a.push(n.to_string());
            }
            match req {
                Request::Calibrate { .. } => Response::Refused(Refusal::Faulted.into()),
                Request::Timing => common::timing(),
                _ => Response::Ok,
            }
        },
        |_| true,
    );
    let mut child = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", &addr, "shell"])
        .args(flags)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{e}"));
    if let Some(mut stdin) = child.stdin.take() {
        let _ = stdin.write_all(b"calibrate weight\nsave\n");
    }
    let o = child.wait_with_output().unwrap_or_else(|e| panic!("{e}"));
    drop(robot);
    let a = acted.lock().map(|a| a.clone()).unwrap_or_default();
    let text =
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    (o.status.success(), text, a)
}

#[test]
fn stop_on_error_sends_nothing_after_a_refusal() {
    let (ok, text, acted) = session(&["--stop-on-error"]);
    assert!(!ok, "{text}");
    assert!(text.contains("stopped at line 1"), "{text}");
    assert!(!acted.contains(&"save".to_string()), "{acted:?}: {text}");
}

#[test]
fn without_it_the_session_goes_on_and_fails_at_the_end() {
    let (ok, text, acted) = session(&[]);
    assert!(!ok, "{text}");
    assert!(
        text.contains("command(s) of the session did not go as written"),
        "{text}"
    );
    assert!(acted.contains(&"save".to_string()), "{acted:?}: {text}");
}
