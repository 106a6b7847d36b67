//! The parameter table's tests: every entry reads its default, writes,
//! is refused out of range by name, and builds; the generated page.
extern crate std;
use super::*;

/// The `controller` entry takes every registered law and no more, its
/// default the apex-regulating energy law: a law added to the registry
/// is selectable without another edit.
#[test]
fn the_controller_entry_spans_the_registered_laws() {
    let c = find("controller").map(|p| (p.min, p.max, p.default));
    assert_eq!(c, Some((0.0, (ControllerKind::ALL.len() - 1) as f32, 5.0)));
    assert_eq!(
        controller_default(CONTROLLER_DEFAULT as usize).map(|s| s.kind()),
        Some(ControllerKind::EnergyApex)
    );
    assert_eq!(CONTROLLER_NAMES.len(), ControllerKind::ALL.len());
}

/// The machine's constants are entries: a set changes the model, and
/// what the model derives follows it unless it was set apart.
#[test]
fn a_model_set_carries_what_follows_from_it() {
    let mut cfg = HopperConfig::default();
    assert_eq!(get(&cfg, "model.body_mass_kg"), Ok(9.0));
    assert_eq!(set(&mut cfg, "model.body_mass_kg", 12.0), Ok(()));
    assert_eq!(cfg.model.body_mass_kg, 12.0);
    assert_eq!(
        set(&mut cfg, "model.body_mass_kg", 0.0),
        Err(ParamError::OutOfRange("model.body_mass_kg"))
    );
    assert!(
        MACHINE.iter().all(|p| !p.live),
        "a machine's constant changes disarmed"
    );
    // The lead, the torque constant, the stroke and the current limit
    // reach the calibration and the supervisor.
    set(&mut cfg, "model.screw_lead_m", 0.01).unwrap_or_else(|e| panic!("{e:?}"));
    set(&mut cfg, "model.torque_constant_nm_per_a", 0.05).unwrap_or_else(|e| panic!("{e:?}"));
    set(&mut cfg, "model.stroke_m", 0.08).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(cfg.calibration.lead_m_per_rev, 0.01);
    assert_eq!(cfg.calibration.torque_constant_nm_per_a, 0.05);
    assert_eq!(cfg.supervisor.nut_stops_m.max, 0.08);
    assert_eq!(
        cfg.supervisor.overcurrent_trip_a,
        10.0 * cfg.model.usable_current_limit_a()
    );
    assert!(cfg.supervisor.stroke_max_m > 0.08);
    // The spring rate follows the model's spring until the bench sets
    // its own; then the model's spring leaves it alone.
    set(&mut cfg, "model.spring_stiffness_n_per_m", 15_000.0).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(cfg.supervisor.spring_rate_n_per_m, 15_000.0);
    set(&mut cfg, "supervisor.spring_rate_n_per_m", 14_200.0).unwrap_or_else(|e| panic!("{e:?}"));
    set(&mut cfg, "model.spring_stiffness_n_per_m", 16_000.0).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(cfg.supervisor.spring_rate_n_per_m, 14_200.0);
    assert!(Hopper::new(cfg).is_ok());
    // The same machine set at once is the same configuration.
    let mut whole = HopperConfig::for_model(cfg.model);
    whole.supervisor.spring_rate_n_per_m = 14_200.0;
    assert_eq!(whole, cfg);
}

#[test]
fn parameters_belong_to_their_controllers() {
    let index = |n: &str| CONTROLLER_NAMES.iter().position(|c| *c == n);
    let of = |name: &str| find(name).and_then(owner).map(|o| o.controller);
    assert_eq!(of("energy.gain_nm_per_j"), index("energy"));
    assert_eq!(of("constant_torque.torque_nm"), index("open-torque"));
    assert_eq!(of("shaped.switch_fraction"), index("shaped"));
    assert_eq!(of("energy_apex.measure"), index("energy-apex"));
    // Every configuration has these.
    for general in ["controller", "target_apex_m", "arming.require_tare"] {
        assert_eq!(find(general).and_then(owner), None, "{general}");
    }
    // Only with the non-default choice, and with the default one.
    let o = find("step_closed.min_compression_m").and_then(owner);
    assert_eq!(o.map(|o| o.controller), index("step-closed"));
    assert_eq!(
        o.and_then(|o| o.choice).map(|(q, v)| (q.name, v)),
        Some(("step_closed.gain", 1))
    );
    let o = find("step_closed.kp_m_per_j").and_then(owner);
    assert_eq!(
        o.and_then(|o| o.choice).map(|(q, v)| (q.name, v)),
        Some(("step_closed.gain", 0))
    );
}

/// Every parameter that some controller's configuration lacks has an
/// owner: none would be reported as "not in the robot's configuration".
#[test]
fn every_controller_parameter_has_an_owner() {
    for i in 0..CONTROLLER_NAMES.len() {
        let cfg = with_controller(i).unwrap_or_else(|| panic!("controller {i}"));
        for p in TABLE {
            if read(&mut { cfg }, p).is_err() {
                assert!(owner(p).is_some(), "{}", p.name);
            }
        }
    }
}
use crate::hopper::Hopper;
use std::string::String;
use std::vec::Vec;

#[test]
fn names_are_unique_and_defaults_in_range() {
    for (i, p) in TABLE.iter().enumerate() {
        assert!(
            p.check(p.default).is_ok(),
            "{}: default out of range",
            p.name
        );
        assert!(p.min <= p.max, "{}", p.name);
        assert!(!p.doc.is_empty() && !p.unit.is_empty(), "{}", p.name);
        for q in &TABLE[i + 1..] {
            assert_ne!(p.name, q.name);
        }
    }
}

/// Every parameter can be read and written once its controller is
/// selected, and reads back its default from a fresh selection: the
/// configuration types' defaults are the table's.
#[test]
fn every_parameter_reads_its_default_and_writes() {
    for p in TABLE {
        let mut cfg = HopperConfig::default();
        // Select the controller the parameter belongs to.
        let owner = owner(p).map(|o| o.controller);
        if let Some(i) = owner {
            set(&mut cfg, CONTROLLER.name, i as f32).unwrap_or_else(|e| panic!("{e:?}"));
        }
        if p.name == STEP_CLOSED_MIN_COMPRESSION_M.name {
            set(&mut cfg, STEP_CLOSED_GAIN.name, 1.0).unwrap_or_else(|e| panic!("{e:?}"));
        }
        let got = get(&cfg, p.name).unwrap_or_else(|e| panic!("{}: {e:?}", p.name));
        if p.name != CONTROLLER.name {
            assert_eq!(
                got, p.default,
                "{}: the type's default is not the table's",
                p.name
            );
        }
        let v = if p.kind == Kind::Real { p.max } else { p.min };
        set(&mut cfg, p.name, v).unwrap_or_else(|e| panic!("{}: {e:?}", p.name));
        assert_eq!(get(&cfg, p.name), Ok(v), "{}", p.name);
    }
    assert_eq!(
        get(&HopperConfig::default(), CONTROLLER.name),
        Ok(CONTROLLER.default)
    );
}

#[test]
fn bad_values_and_names_are_refused() {
    let mut cfg = HopperConfig::default();
    assert_eq!(set(&mut cfg, "no.such", 1.0), Err(ParamError::Unknown));
    assert_eq!(
        set(&mut cfg, FLIGHT_KP.name, -1.0),
        Err(ParamError::OutOfRange(FLIGHT_KP.name))
    );
    assert_eq!(
        set(&mut cfg, FLIGHT_KP.name, f32::NAN),
        Err(ParamError::OutOfRange(FLIGHT_KP.name))
    );
    assert_eq!(
        set(&mut cfg, CONTROLLER.name, 2.5),
        Err(ParamError::OutOfRange(CONTROLLER.name))
    );
    // The default controller is energy-apex: a shaped constant is refused.
    assert_eq!(
        set(&mut cfg, SHAPED_BRAKE_FRACTION.name, 0.5),
        Err(ParamError::NotSelected(SHAPED_BRAKE_FRACTION.name))
    );
    assert_eq!(
        cfg,
        HopperConfig::default(),
        "a refused set changed nothing"
    );
}

#[test]
fn a_configuration_set_within_the_table_builds() {
    for i in 0..CONTROLLER_NAMES.len() {
        let mut cfg = HopperConfig::default();
        set(&mut cfg, CONTROLLER.name, i as f32).unwrap_or_else(|e| panic!("{e:?}"));
        for p in TABLE {
            if p.name == CONTROLLER.name || get(&cfg, p.name).is_err() {
                continue;
            }
            let mut c = cfg;
            // Sensor, estimator and supervisor limits have cross-field
            // rules (a range's min below its max, the liftoff threshold
            // below the touchdown one, ...) that one value at its bound
            // may break: the construction must then refuse, not panic.
            let coupled = ["estimator.", "supervisor.", "calibration.", "thermal."]
                .iter()
                .any(|prefix| p.name.starts_with(prefix));
            for v in [p.min, p.max, p.default] {
                if coupled {
                    set(&mut c, p.name, v).unwrap_or_else(|e| panic!("{e:?}"));
                    let _ = Hopper::new(c);
                    continue;
                }
                set(&mut c, p.name, v).unwrap_or_else(|e| panic!("{e:?}"));
                // The flight start must lie on the stroke: the one
                // cross-field rule beyond the table's ranges (checked
                // by the flight PD's own test).
                if p.name == FLIGHT_START_M.name && v > c.model.stroke_m {
                    continue;
                }
                assert!(
                    Hopper::new(c).is_ok(),
                    "{} = {v}: {:?}",
                    p.name,
                    Hopper::new(c).err()
                );
            }
        }
    }
}

/// Every entry's range is enforced with no code of its own: a value
/// out of range put straight into its slot (past `set`'s check) makes
/// [`validate`] name that entry and `Hopper::new` refuse the
/// configuration, for every controller's parameters.
#[test]
fn every_entry_out_of_range_is_refused_by_name() {
    let mut checked = 0;
    for i in 0..CONTROLLER_NAMES.len() {
        let cfg = with_controller(i).unwrap_or_else(|| panic!("controller {i}"));
        assert_eq!(validate(&cfg), Ok(()), "defaults of controller {i}");
        for p in TABLE {
            let mut c = cfg;
            let put = match slot(&mut c, p) {
                Some(Slot::Real(v)) => {
                    *v = f32::NAN;
                    true
                }
                // Below the least count (flags and choices cannot be
                // out of range).
                Some(Slot::U32(n)) if p.min >= 1.0 => {
                    *n = 0;
                    true
                }
                Some(Slot::U16(n)) if p.min >= 1.0 => {
                    *n = 0;
                    true
                }
                Some(Slot::U8(n)) if p.min >= 1.0 => {
                    *n = 0;
                    true
                }
                _ => false,
            };
            if !put {
                continue;
            }
            assert_eq!(validate(&c), Err(InvalidField(p.name)), "{}", p.name);
            assert!(Hopper::new(c).is_err(), "{} = NaN was built", p.name);
            checked += 1;
        }
    }
    // Every real and count entry of some controller was tried.
    assert!(checked >= 100, "{checked}");
}

/// The parameter table as Markdown (`docs/parameters.md`).
pub fn markdown() -> String {
    let mut s = String::from(
        "# Runtime parameters\n\n\
         Generated from the parameter table (`hopper_control::params::TABLE`) by\n\
         `HOPPER_WRITE_DOCS=1 cargo test -p hopper-control params_doc`; a test fails when this\n\
         page is stale. Live: may change while the motor is driven; otherwise only with\n\
         the amplifier disabled. Flags are 0/1, choices the index of a name.\n\n\
         | Name | Unit | Range | Default | Live | What |\n\
         |------|------|-------|---------|------|------|\n",
    );
    for p in TABLE {
        // Large bounds (1e30: a check turned off) in exponent form.
        let num = |v: f32| {
            if v.abs() >= 1e7 {
                std::format!("{v:e}")
            } else {
                std::format!("{v}")
            }
        };
        let range = match p.kind {
            Kind::Choice(names) => names.join(", "),
            Kind::Flag => String::from("0, 1"),
            _ => std::format!("{} ..= {}", num(p.min), num(p.max)),
        };
        let default = match p.kind {
            Kind::Choice(names) => String::from(names[p.default as usize]),
            _ => num(p.default),
        };
        s += &std::format!(
            "| `{}` | {} | {} | {} | {} | {} |\n",
            p.name,
            p.unit,
            range,
            default,
            if p.live { "yes" } else { "no" },
            // A `|` would end the table cell.
            p.doc.replace('|', "\\|")
        );
    }
    s
}

#[test]
fn params_doc_is_current() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/parameters.md");
    let want = markdown();
    if std::env::var_os("HOPPER_WRITE_DOCS").is_some() {
        std::fs::write(path, &want).unwrap_or_else(|e| panic!("{path}: {e}"));
    }
    let have = std::fs::read_to_string(path).unwrap_or_default();
    let stale: Vec<_> = want.lines().filter(|l| !have.contains(l)).take(3).collect();
    assert!(
        have == want,
        "docs/parameters.md is stale (first differing lines: {stale:?}); regenerate with \
         `HOPPER_WRITE_DOCS=1 cargo test -p hopper-control params_doc`"
    );
}
