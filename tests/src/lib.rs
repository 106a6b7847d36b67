//! Host software-in-the-loop tests live in `tests/`; this library holds what
//! several of them share: the canonical `hopper-sim run --json` runs, built
//! the way the command line builds them, and the rounding that makes their
//! JSON snapshots exact on one machine yet immune to printing noise.
//!
//! The snapshots (`tests/snapshots/*.snap`, insta) pin every figure of the
//! three canonical runs. A change meant to move them: rerun with
//! `INSTA_UPDATE=always cargo test -p sil-tests`, then read the diff of the
//! `.snap` files and list each change with its reason in the commit.

use hal_sim::controller::{ControllerSpec, PlantDriver};
use hal_sim::run::{run, Summary};
use hal_sim::scenario::{Overrides, Settings};
use hal_sim::Params;
use hopper_control::laws::ControllerKind;

/// The flags of one `hopper-sim run ... --json` that a test pins down. A
/// field left `None` is a flag not given, so the command line's default
/// applies, exactly as for the real command.
#[derive(Clone, Copy, Debug, Default)]
pub struct CliRun<'a> {
    /// `--params`: a preset or a TOML file.
    pub params: Option<&'a str>,
    /// `--controller`.
    pub controller: Option<ControllerKind>,
    /// `--start-apex`, m.
    pub start_apex_m: Option<f64>,
    /// `--target-apex`, m.
    pub target_apex_m: Option<f64>,
    /// `--duration`, s.
    pub duration_s: Option<f64>,
    /// `--set NAME=VALUE`s: firmware parameters.
    pub set: &'a [(&'static hopper_control::params::Param, f32)],
}

/// The environment variable that points the closed-loop tests at a HIL
/// target: `tcp:HOST:PORT` (`hopper-hil` on QEMU) or `serial:PORT` (on a
/// board), e.g. `HOPPER_HIL=serial:/dev/ttyUSB0 cargo test -p sil-tests
/// --test closed_loop --test shaped -- --test-threads 1`.
pub const HIL_TARGET_VAR: &str = "HOPPER_HIL";

/// The firmware a closed-loop test runs against the plant: the control
/// crate in this process, or, with [`HIL_TARGET_VAR`] set, the HIL image
/// at that address, configured over its link for `spec` (one run at a
/// time: run the tests with `--test-threads 1`).
pub fn firmware(
    spec: &ControllerSpec,
    params: &Params,
    start_apex_m: f64,
    dt_s: f64,
) -> Result<Box<dyn PlantDriver>, String> {
    match std::env::var(HIL_TARGET_VAR) {
        Ok(target) => {
            let connection =
                hal_sim::hil::Connection::named(&target, std::time::Duration::from_secs(5))?;
            Ok(Box::new(spec.build_hil(
                params,
                start_apex_m,
                dt_s,
                connection,
            )?))
        }
        Err(_) => Ok(Box::new(spec.build(params, start_apex_m, dt_s)?)),
    }
}

/// `--set thermal.protect=0`: the motor's thermal protection off, for the
/// tests that study a control law past the motor's thermal limit (on the
/// design machine every law derates within 8 to 27 s: `tests/thermal.rs`
/// and `docs/safety.md`). The estimate still runs and is reported.
pub const NO_THERMAL_LIMIT: [(&hopper_control::params::Param, f32); 1] =
    [(&hopper_control::params::THERMAL_PROTECT, 0.0)];

impl CliRun<'_> {
    /// Runs it through the same layers `hopper-sim run` uses (flags as
    /// [`Overrides`] over the defaults, the same checks, no trajectory
    /// samples as without `--out`), so that the summary serialises to the
    /// very JSON the command prints.
    pub fn run(&self) -> Result<Summary, String> {
        let plant = match self.params {
            Some(p) => Some(hal_sim::params_toml::load(p).map_err(|e| e.to_string())?),
            None => None,
        };
        let flags = Overrides {
            plant,
            controller: self.controller,
            start_apex_m: self.start_apex_m,
            target_apex_m: self.target_apex_m,
            duration_s: self.duration_s,
            firmware_params: (!self.set.is_empty()).then(|| self.set.to_vec()),
            ..Overrides::default()
        };
        let settings = Settings::resolve(None, &flags);
        settings.check()?;
        let cfg = settings.run_config(0.0);
        let mut ctl = settings
            .controller_spec()
            .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))?;
        run(&cfg, &settings.params_name, &mut ctl)
            .map(|r| r.summary)
            .map_err(|e| e.to_string())
    }
}

/// Significant digits kept of every non-integer number in a snapshot: a
/// change larger than about 1e-9 relative shows, while the last bits a
/// float's shortest printing depends on do not.
pub const SNAPSHOT_SIGNIFICANT_DIGITS: usize = 10;

/// `summary`'s `--json` form, pretty-printed, with every float rounded to
/// [`SNAPSHOT_SIGNIFICANT_DIGITS`]; integers (hop counts, indices) stay exact.
///
/// It goes through the printed text, as the command prints it: the f32
/// figures of the firmware's ledger are printed as f32 (`0.09230099`), which
/// `serde_json::to_value` would widen to f64 digits the command never shows.
/// The snapshot is this text, not a `serde_json::Value` handed to insta:
/// a workspace build turns on serde_json's `arbitrary_precision` (through
/// xtask's defmt-decoder), under which insta would record every number as a
/// one-key map, so the same run would snapshot differently under
/// `cargo test -p sil-tests` and `cargo test --workspace`.
pub fn snapshot_text(summary: &Summary) -> Result<String, serde_json::Error> {
    let text = serde_json::to_string(summary)?;
    let value = round_floats(serde_json::from_str(&text)?);
    serde_json::to_string_pretty(&value)
}

/// Rounds every float in `v` to [`SNAPSHOT_SIGNIFICANT_DIGITS`] and puts
/// object keys in sorted order (whether or not serde_json's `preserve_order`
/// is on in a build).
pub fn round_floats(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            // `{:.9e}` prints 1 + 9 significant digits; parsing it back is
            // the correctly rounded value, without a hand-made power of 10.
            let text = format!("{x:.*e}", SNAPSHOT_SIGNIFICANT_DIGITS - 1);
            text.parse::<f64>().map_or(Value::Null, Value::from)
        }
        Value::Array(a) => Value::Array(a.into_iter().map(round_floats).collect()),
        Value::Object(o) => {
            let mut entries: Vec<(String, Value)> = o.into_iter().collect();
            entries.sort_by(|a, b| a.0.cmp(&b.0));
            Value::Object(
                entries
                    .into_iter()
                    .map(|(k, x)| (k, round_floats(x)))
                    .collect(),
            )
        }
        other => other,
    }
}
