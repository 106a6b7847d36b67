//! The bring-up order: the one sequence of routines, mount moves and the
//! save that calibrates a new robot, stated here once. The cockpit's
//! guided sequence is built from it; `hopper-link calibrate --help`, the
//! book's bring-up page (`docs/bring-up.md`, run in CI against a
//! mis-calibrated virtual robot) and the CI session
//! (`tests/link-session.txt`) are checked equal to it by a test
//! (`link/tests/bringup_order.rs`).
//!
//! Why this order: the hoisted routines first, since a standing robot's
//! weight on the leg would read as an offset. The direction check before
//! homing (homing drives the nut up and needs the right sign); a tare
//! before the spring sweep (the supervisor's spring cross-check sees an
//! offset and a rate error together at the sweep's bottom), and again
//! after it with the rate the sweep found. Then standing: the weighing (the
//! load cell's gain, from the robot's known weight) and the height zero;
//! then the save.

/// Where the robot must be for a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mount {
    /// Anywhere, held still.
    Any,
    /// Hanging on the hoist, the toe free.
    Hoist,
    /// Standing on its toe, the body free.
    Standing,
}

impl Mount {
    /// As the guides say it.
    pub fn text(self) -> &'static str {
        match self {
            Mount::Any => "anywhere, still",
            Mount::Hoist => "on the hoist, toe free",
            Mount::Standing => "standing on its toe, the body free",
        }
    }
}

/// One step of the bring-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// The `hopper-link` command (a routine, a mount move or `save`).
    pub command: &'static str,
    /// Where the robot must be.
    pub mount: Mount,
    /// What it does, in a line.
    pub what: &'static str,
}

impl Step {
    /// The routine it runs (`Some("tare")` for `calibrate tare`; `save` for
    /// the save), or `None` for a mount move.
    pub fn routine(&self) -> Option<&'static str> {
        if self.command == "save" {
            Some("save")
        } else {
            self.command.strip_prefix("calibrate ")
        }
    }
}

/// The bring-up, in order. `mount release` is the simulated robot's move
/// from the hoist to standing (on a real robot: lower it onto its toe).
pub const STEPS: &[Step] = &[
    Step {
        command: "calibrate sensors",
        mount: Mount::Any,
        what: "every channel's raw codes and noise, the encoders still",
    },
    Step {
        command: "calibrate direction",
        mount: Mount::Hoist,
        what: "a 2 A pulse must move the nut down and compress the spring",
    },
    Step {
        command: "calibrate home",
        mount: Mount::Hoist,
        what: "the nut driven to its upper stop, the motor encoder zeroed there",
    },
    Step {
        command: "calibrate tare",
        mount: Mount::Hoist,
        what: "the load cell's and the potentiometer's offsets",
    },
    Step {
        command: "calibrate spring",
        mount: Mount::Hoist,
        what: "a 10 mm nut sweep: the spring rate by least squares",
    },
    Step {
        command: "calibrate tare",
        mount: Mount::Hoist,
        what: "again, with the rate the sweep found",
    },
    Step {
        command: "mount release",
        mount: Mount::Standing,
        what: "lower the robot onto its toe (the simulated robot: `mount release`)",
    },
    Step {
        command: "calibrate weight",
        mount: Mount::Standing,
        what: "a nut sweep lifting the body: its weight, hence the load cell's gain",
    },
    Step {
        command: "calibrate height",
        mount: Mount::Standing,
        what: "the height encoder's origin",
    },
    Step {
        command: "save",
        mount: Mount::Any,
        what: "the calibration to the robot's flash (it loads at every boot)",
    },
];

/// The routines and the save, in order (the mount moves left out): what
/// `calibrate --help` lists and the cockpit's buttons run.
pub fn routines() -> impl Iterator<Item = &'static str> {
    STEPS.iter().filter_map(Step::routine)
}

/// The cockpit's guided sequence as a JavaScript array literal:
/// `[routine, where and what]` per routine.
pub fn cockpit_steps_js() -> String {
    let rows: Vec<String> = STEPS
        .iter()
        .filter_map(|s| {
            s.routine().map(|r| {
                let text = if r == "save" {
                    s.what.to_string()
                } else {
                    format!("{}: {}", s.mount.text(), s.what)
                };
                format!(
                    "[{},{}]",
                    serde_json::Value::from(r),
                    serde_json::Value::from(text)
                )
            })
        })
        .collect();
    format!("[{}]", rows.join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_order_hoists_first_and_saves_last() {
        let r: Vec<_> = routines().collect();
        assert_eq!(
            r,
            [
                "sensors",
                "direction",
                "home",
                "tare",
                "spring",
                "tare",
                "weight",
                "height",
                "save"
            ]
        );
        // Every hoisted step comes before every standing one.
        let last_hoist = STEPS.iter().rposition(|s| s.mount == Mount::Hoist);
        let first_standing = STEPS.iter().position(|s| s.mount == Mount::Standing);
        assert!(last_hoist < first_standing);
        let js = cockpit_steps_js();
        assert!(js.starts_with("[[\"sensors\",\"anywhere, still: "), "{js}");
        assert_eq!(js.matches("],[").count(), 8);
    }
}
