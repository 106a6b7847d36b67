//! The firmware's runtime parameters, each defined once: name, unit, range,
//! default, whether it may change while the motor is driven, and a one-line
//! doc.
//!
//! Each parameter is declared once, as a field of the configuration type
//! that holds it, with `param::config!` (`laws/shaped.rs`, `estimator.rs`,
//! ...): that one line gives the field, its default, its doc, its entry
//! (number on the link, name, unit, kind, range, whether it may change
//! armed) and where it lives in its type. This module sits above the
//! configurations it lists (nothing they are made of imports it): it says
//! where each type lives in a whole configuration (`groups!`), and
//! [`TABLE`] gathers the entries by number, the link exposes exactly it, the host tools (`hopper-sim`'s
//! `--set`, scenario files and sweeps) look parameters up in it by name,
//! [`validate`] is the one range check of a configuration, and
//! `docs/parameters.md` is generated from it (a test fails when the page is
//! stale).
//!
//! Not parameters: what follows from the model (the overcurrent trip at 10x
//! the current limit, the stroke soft limits with the braking deceleration
//! they assume, the stops, the calibration's lead and torque constant) and
//! board facts (counter and converter widths). Estimator, supervisor,
//! calibration, bring-up and thermal entries change only with the amplifier
//! disabled.
//!
//! Every value is an `f32`: a flag is 0 or 1, a choice is the index of one
//! of its names, a count is a whole number. [`get`] and [`set`] read and
//! write a [`HopperConfig`] by name; a parameter of a controller other than
//! the selected one is refused by [`set`] (select the controller first:
//! that starts it from its defaults).

use crate::config::HopperConfig;
use crate::laws::{
    energy, energy_apex, modified_torque, open_torque, shaped, step_closed, step_open, velocity,
    ControllerKind, StanceLaw, Strategy,
};
use crate::param::Slot;
pub use crate::param::{Choice, InvalidField, Kind, Param};

/// Every parameter, in the order the docs list them (a parameter's index
/// here is its number on the link).
pub static TABLE: &[&Param] = &GATHERED;

/// The configuration types that declare parameters (`config!`), each with
/// where it lives in a whole configuration: their entries are re-exported
/// here and gathered into [`TABLE`], and their slots reached through
/// [`SLOTS`].
macro_rules! groups {
    ($($($module:ident)::+ => |$c:ident| $reach:expr,)*) => {
        $(
            pub use $($module)::+::entries::*;
        )*

        /// Every group of entries.
        const GROUPS: &[&[&Param]] = &[$($($module)::+::PARAMS),*];

        /// Each group's entries' slots in a whole configuration, by the
        /// entry's index in its group.
        const SLOTS: &[for<'a> fn(&'a mut HopperConfig, usize) -> Option<Slot<'a>>] = &[$(
            |$c, i| ($reach).and_then(|s| $($module)::+::FIELDS.get(i).and_then(|f| (f.slot)(s))),
        )*];
    };
}

groups!(
    crate::config => |c| Some(c),
    crate::laws::flight_pd => |c| Some(&mut c.flight),
    crate::laws::energy => |c| energy(c),
    crate::laws::open_torque => |c| open_torque(c),
    crate::laws::modified_torque => |c| modified_torque(c),
    crate::laws::step_open => |c| step_open(c),
    crate::laws::step_closed => |c| step_closed(c),
    crate::laws::velocity => |c| velocity(c),
    crate::laws::energy_apex => |c| energy_apex(c),
    crate::laws::shaped => |c| shaped(c),
    crate::estimator => |c| Some(&mut c.estimator),
    crate::arming => |c| Some(&mut c.arming),
    crate::bringup => |c| Some(&mut c.bringup),
    crate::supervisor => |c| Some(&mut c.supervisor),
    crate::debounce => |c| Some(&mut c.estop),
    crate::thermal => |c| Some(&mut c.supervisor.thermal),
    crate::calibration => |c| Some(&mut c.calibration),
    crate::model => |c| Some(&mut c.model),
);

/// How many parameters there are.
// Evaluated by the compiler only: an index out of bounds is a build error.
#[allow(clippy::indexing_slicing)]
const COUNT: usize = {
    let mut n = 0;
    let mut l = 0;
    while l < LISTS.len() {
        let mut g = 0;
        while g < LISTS[l].len() {
            n += LISTS[l][g].len();
            g += 1;
        }
        l += 1;
    }
    n
};

/// The groups of entries: the configurations' above and the laws added to
/// the registry (`laws!`), each declared in its law's file.
const LISTS: [&[&[&Param]]; 2] = [GROUPS, crate::laws::ADDED_PARAMS];

/// [`TABLE`] as an array: the groups' entries placed by their numbers.
static GATHERED: [&Param; COUNT] = gather(&LISTS).0;

/// Where each entry of [`TABLE`] is declared, by number: its list (0 the
/// configurations' groups, 1 the added laws), its group, its index there.
static PLACES: [Place; COUNT] = gather(&LISTS).1;

/// Where an entry is declared (see [`PLACES`]).
#[derive(Clone, Copy)]
struct Place {
    list: u8,
    group: u8,
    index: u8,
}

/// Places each entry of `lists` at its number, refusing (at compile time)
/// a number given twice or a number past the end (with `N` the number of
/// entries, that also leaves no gap), and where each was declared.
/// Evaluated by the compiler only: an index out of bounds or a failed
/// check is a build error.
#[allow(clippy::indexing_slicing)]
const fn gather<const N: usize>(
    lists: &[&[&[&'static Param]]],
) -> ([&'static Param; N], [Place; N]) {
    let mut out = [lists[0][0][0]; N];
    let mut places = [Place {
        list: 0,
        group: 0,
        index: 0,
    }; N];
    let mut placed = [false; N];
    let mut l = 0;
    while l < lists.len() {
        let groups = lists[l];
        let mut g = 0;
        while g < groups.len() {
            let mut i = 0;
            while i < groups[g].len() {
                let p = groups[g][i];
                let n = p.number as usize;
                assert!(n < N, "a parameter's number is past the end of the table");
                assert!(!placed[n], "two parameters have the same number");
                assert!(g < 256 && i < 256, "a group of more than 255 entries");
                out[n] = p;
                places[n] = Place {
                    list: l as u8,
                    group: g as u8,
                    index: i as u8,
                };
                placed[n] = true;
                i += 1;
            }
            g += 1;
        }
        l += 1;
    }
    (out, places)
}

/// Where `p` lives in `c`: `None` when it belongs to a controller other
/// than the selected one (or a choice's other variant).
fn slot<'a>(c: &'a mut HopperConfig, p: &Param) -> Option<Slot<'a>> {
    let place = PLACES.get(usize::from(p.number))?;
    let (group, index) = (usize::from(place.group), usize::from(place.index));
    if place.list == 0 {
        SLOTS.get(group).and_then(|f| f(c, index))
    } else {
        crate::laws::added_slot(&mut c.strategy, group, index)
    }
}

/// The controllers [`CONTROLLER`] chooses from, by name (the index is the
/// value): the law registry's ([`ControllerKind::NAMES`]).
pub const CONTROLLER_NAMES: &[&str] = ControllerKind::NAMES;

/// The top of [`CONTROLLER`]'s range: the last registered law's index (a
/// law added to [`ControllerKind`] widens it).
pub const CONTROLLER_MAX: f32 = ControllerKind::MAX_INDEX;

/// [`CONTROLLER`]'s default: the apex-regulating energy law.
pub const CONTROLLER_DEFAULT: f32 = ControllerKind::DEFAULT_INDEX;

/// The machine's constants (`model.*`): a configuration given whole (a
/// robot file, a saved record, a hardware-in-the-loop run) sets them
/// first, so that what follows from the model and is set apart afterwards
/// stays as set ([`HopperConfig::follow_model`]).
pub const MACHINE: &[&Param] = crate::model::PARAMS;

/// Whether `p` is one of the machine's constants ([`MACHINE`]).
pub fn is_machine(p: &Param) -> bool {
    MACHINE.iter().any(|m| m.number == p.number)
}

/// The master switches of protections, each with its safe value: a real
/// robot's link refuses any other value (a simulator keeps them, for
/// control studies). The protections' thresholds (`thermal.*`, the link
/// timeout) stay settable within their ranges: they are the motor's and
/// the bench's data, which a user must be able to enter.
pub const PROTECTIONS: [(&Param, f32); 2] = [(&THERMAL_PROTECT, 1.0), (&ARM_UNTETHERED, 0.0)];

/// The parameter called `name`.
pub fn find(name: &str) -> Option<&'static Param> {
    TABLE.iter().copied().find(|p| p.name == name)
}

/// Why [`get`] or [`set`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// No parameter has this name.
    Unknown,
    /// The value is outside the parameter's range (or not whole).
    OutOfRange(&'static str),
    /// The parameter belongs to a controller other than the selected one.
    NotSelected(&'static str),
}

/// The index of the controller `strategy` is (the [`CONTROLLER`] value).
pub fn controller_index(strategy: &Strategy) -> usize {
    let kind = strategy.kind();
    ControllerKind::ALL
        .iter()
        .position(|k| *k == kind)
        .unwrap_or(0)
}

/// The controller at `index` of [`CONTROLLER_NAMES`], with its defaults.
pub fn controller_default(index: usize) -> Option<Strategy> {
    ControllerKind::ALL.get(index).map(|k| k.default_strategy())
}

/// The selected controller's configuration, if it is the one named: a
/// controller's parameters exist only while it is selected.
macro_rules! selected {
    ($($(#[$meta:meta])* $fn:ident => $pattern:pat => $cfg:ident: $ty:ty;)*) => {$(
        $(#[$meta])*
        pub(crate) fn $fn(c: &mut HopperConfig) -> Option<&mut $ty> {
            match &mut c.strategy {
                $pattern => Some($cfg),
                _ => None,
            }
        }
    )*};
}

selected! {
    energy => Strategy::Thesis(StanceLaw::Energy(s)) => s: energy::Config;
    open_torque => Strategy::Thesis(StanceLaw::OpenTorque(s)) => s: open_torque::Config;
    modified_torque => Strategy::Thesis(StanceLaw::ModifiedTorque(s)) => s: modified_torque::Config;
    step_open => Strategy::Thesis(StanceLaw::StepOpen(s)) => s: step_open::Config;
    step_closed => Strategy::Thesis(StanceLaw::StepClosed(s)) => s: step_closed::Config;
    velocity => Strategy::Thesis(StanceLaw::Velocity(s)) => s: velocity::Config;
    energy_apex => Strategy::EnergyApex(s) => s: energy_apex::ApexLoop;
    shaped => Strategy::Shaped(s) => s: shaped::Config;
}

/// The value of parameter `name` in `cfg`.
pub fn get(cfg: &HopperConfig, name: &str) -> Result<f32, ParamError> {
    let p = find(name).ok_or(ParamError::Unknown)?;
    let mut c = *cfg;
    read(&mut c, p)
}

/// [`get`] by table entry, through a configuration the caller lends
/// mutably (the slots are reached by `&mut`; nothing is changed): reading
/// many parameters costs no lookups by name and no copies.
pub fn read(c: &mut HopperConfig, p: &Param) -> Result<f32, ParamError> {
    let index = controller_index(&c.strategy);
    let at = slot(c, p).ok_or(ParamError::NotSelected(p.name))?;
    // The controller is the strategy's variant.
    Ok(crate::param::value_of(at).unwrap_or(index as f32))
}

/// Checks every parameter `cfg` holds against its entry's range (and
/// wholeness), naming the first one out of range in table order: the
/// range check of a whole configuration (`Hopper::new` runs it; each part
/// checks its own entries in place, `param::validate_fields`).
pub fn validate(cfg: &HopperConfig) -> Result<(), InvalidField> {
    check_in(&mut { *cfg })
}

/// [`validate`] through a configuration lent mutably (the slots are
/// reached by `&mut`; nothing is changed).
#[inline(never)]
fn check_in(cfg: &mut HopperConfig) -> Result<(), InvalidField> {
    for p in TABLE {
        // A parameter of another controller is not in `cfg` to check.
        if let Ok(v) = read(cfg, p) {
            p.check(v)?;
        }
    }
    Ok(())
}

/// Sets parameter `name` of `cfg` to `value`, after checking it against the
/// parameter's range. The whole configuration is validated again when a
/// controller is built from it (`Hopper::new`).
pub fn set(cfg: &mut HopperConfig, name: &str, value: f32) -> Result<(), ParamError> {
    write(cfg, find(name).ok_or(ParamError::Unknown)?, value)
}

/// [`set`] by table entry. A `model.*` entry also re-derives what follows
/// from the model ([`HopperConfig::follow_model`]).
pub fn write(cfg: &mut HopperConfig, p: &Param, value: f32) -> Result<(), ParamError> {
    let v = p.check(value).map_err(|f| ParamError::OutOfRange(f.0))?;
    if is_machine(p) {
        let old = cfg.model;
        write_slot(cfg, p, v)?;
        cfg.follow_model(&old);
        return Ok(());
    }
    write_slot(cfg, p, v)
}

/// Puts `v`, already checked against `p`'s range, where `p` lives in `cfg`.
fn write_slot(cfg: &mut HopperConfig, p: &Param, v: f32) -> Result<(), ParamError> {
    let at = slot(cfg, p).ok_or(ParamError::NotSelected(p.name))?;
    if !crate::param::put(at, v) {
        // The controller: selecting one starts it from its defaults.
        cfg.strategy = controller_default(v as usize).ok_or(ParamError::OutOfRange(p.name))?;
    }
    Ok(())
}

/// Where a parameter lives: the controller whose configuration holds it,
/// and a choice of that controller it needs (`step_closed.min_compression_m`
/// exists only with `step_closed.gain` normalised).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Owner {
    /// The controller, an index of [`CONTROLLER_NAMES`].
    pub controller: usize,
    /// The choice of that controller and the value it must have.
    pub choice: Option<(&'static Param, usize)>,
}

/// The configuration of controller `index` at its defaults.
fn with_controller(index: usize) -> Option<HopperConfig> {
    let mut cfg = HopperConfig::default();
    write(&mut cfg, &CONTROLLER, index as f32).ok()?;
    Some(cfg)
}

/// Whether `p` is in `cfg` with choice `q` set to `v`.
fn readable_with(cfg: &HopperConfig, q: &Param, v: usize, p: &Param) -> bool {
    let mut c = *cfg;
    write(&mut c, q, v as f32).is_ok() && read(&mut c, p).is_ok()
}

/// The choices (other than the controller) that `cfg` has, with their
/// number of values.
fn choices_of(cfg: &HopperConfig) -> impl Iterator<Item = (&'static Param, usize)> + '_ {
    TABLE.iter().copied().filter_map(move |q| match q.kind {
        Kind::Choice(values) if q.number != CONTROLLER.number && read(&mut { *cfg }, q).is_ok() => {
            Some((q, values.len()))
        }
        _ => None,
    })
}

/// Which controller (and choice) `p` belongs to; `None` for a parameter of
/// every configuration (`target_apex_m`, `arming.*`). Found by trying the
/// configurations themselves rather than from the names, so a new
/// controller or choice needs no change here. The link answers it
/// (`ParamMeta`) so the host can say what would make a parameter active.
pub fn owner(p: &Param) -> Option<Owner> {
    let n = CONTROLLER_NAMES.len();
    // Readable in some variant of a configuration: at its defaults, or
    // with one of its choices switched.
    let has = |i: usize| {
        with_controller(i).is_some_and(|cfg| {
            read(&mut { cfg }, p).is_ok()
                || choices_of(&cfg).any(|(q, k)| (0..k).any(|v| readable_with(&cfg, q, v, p)))
        })
    };
    if (0..n).all(has) {
        return None;
    }
    let controller = (0..n).find(|&i| has(i))?;
    let cfg = with_controller(controller)?;
    // A choice of the controller that some of its values leave `p` out of.
    let choice = choices_of(&cfg).find_map(|(q, k)| {
        let first = (0..k).find(|&v| readable_with(&cfg, q, v, p))?;
        (!(0..k).all(|v| readable_with(&cfg, q, v, p))).then_some((q, first))
    });
    Some(Owner { controller, choice })
}

#[cfg(test)]
mod tests;
