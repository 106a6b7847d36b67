//! The firmware's runtime parameters, each defined once: name, unit, range,
//! default, whether it may change while the motor is driven, and a one-line
//! doc.
//!
//! Each parameter is declared once, as a field of the configuration type
//! that holds it, with `config!` (`laws/shaped.rs`, `estimator.rs`, ...):
//! that one line gives the field, its default, its doc, its entry here
//! (number on the link, name, unit, kind, range, whether it may change
//! armed) and its slot for get/set by name. [`TABLE`] gathers the entries by
//! number, the link exposes exactly it, the host tools (`hopper-sim`'s
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

use crate::hopper::HopperConfig;
use crate::laws::{
    energy, energy_apex, modified_torque, open_torque, shaped, step_closed, step_open, velocity,
    ControllerKind, InvalidField, StanceLaw, Strategy,
};

/// What kind of value a parameter holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// A real number in its unit.
    Real,
    /// A whole number (counts, samples, codes).
    Count,
    /// 0 (off) or 1 (on).
    Flag,
    /// The index of one of these names.
    Choice(&'static [&'static str]),
}

/// One runtime parameter.
#[derive(Debug, Clone, Copy)]
pub struct Param {
    /// Its number on the link: its index in [`TABLE`]. Given in the
    /// declaration, so a parameter added later (at the end) leaves every
    /// other parameter's number as it was.
    pub number: u16,
    /// Name, as a path in the configuration (`flight.kp_a_per_rad`).
    pub name: &'static str,
    /// Unit (SI; `1` for a dimensionless number, `-` for flags and choices).
    pub unit: &'static str,
    /// The value's kind.
    pub kind: Kind,
    /// Smallest allowed value (inclusive).
    pub min: f32,
    /// Largest allowed value (inclusive).
    pub max: f32,
    /// The default.
    pub default: f32,
    /// Whether it may change while the motor is driven (armed); otherwise
    /// only while the amplifier is disabled.
    pub live: bool,
    /// One line: what it is, and where it comes from (thesis equation);
    /// empty in the firmware image.
    pub doc: &'static str,
    /// Where the value lives in a [`HopperConfig`]; `None` when it belongs
    /// to a controller other than the selected one.
    pub(crate) slot: SlotFn,
}

/// The lookup of a parameter's value in a configuration.
pub(crate) type SlotFn = for<'a> fn(&'a mut HopperConfig) -> Option<Slot<'a>>;

impl PartialEq for Param {
    /// One parameter per number (a const check on [`TABLE`]).
    fn eq(&self, other: &Self) -> bool {
        self.number == other.number && self.name == other.name
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Param {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "{=str}", self.name)
    }
}

impl Param {
    /// `v` if it is finite and within `min..=max` (and whole for counts,
    /// flags and choices), else this parameter's name.
    pub fn check(&self, v: f32) -> Result<f32, InvalidField> {
        let whole = !matches!(self.kind, Kind::Real);
        let ok =
            v.is_finite() && v >= self.min && v <= self.max && (!whole || v == libm::truncf(v));
        if ok {
            Ok(v)
        } else {
            Err(InvalidField(self.name))
        }
    }

    /// The default of a flag.
    pub const fn default_flag(&self) -> bool {
        self.default != 0.0
    }
}

/// May change while the motor is driven.
pub(crate) const LIVE: bool = true;
/// Changes only while the amplifier is disabled.
pub(crate) const DISARMED: bool = false;

/// One parameter's entry: `NUMBER ID { name, unit, kind, [min, max],
/// default, LIVE | DISARMED, doc }, |cfg| slot`, where `slot` is where the
/// value lives in a [`HopperConfig`] (`None` when it belongs to a
/// controller other than the selected one). The configuration types
/// declare their parameters with `config!`, which writes these.
macro_rules! entry {
    (
        $(#[$meta:meta])*
        $number:literal $id:ident {
            $name:literal, $unit:literal, $kind:expr, [$min:expr, $max:expr], $default:expr,
            $live:ident, $doc:literal $(,)?
        },
        |$c:ident| $slot:expr
    ) => {
        $(#[$meta])*
        #[doc = $doc]
        pub const $id: $crate::params::Param = $crate::params::Param {
            number: $number,
            name: $name,
            unit: $unit,
            kind: {
                #[allow(unused_imports)]
                use $crate::params::Kind::{self, Count, Flag, Real};
                $kind
            },
            min: $min,
            max: $max,
            default: $default,
            live: $crate::params::$live,
            // The firmware image carries no docs (the host tools and
            // docs/parameters.md do): the link's table needs names and
            // units only, and the docs were 7 KB of flash.
            doc: if cfg!(target_os = "none") { "" } else { $doc },
            slot: |$c| {
                #[allow(unused_imports)]
                use $crate::params::Slot::{self, Flag as B, Real as R};
                $slot
            },
        };
    };
}
pub(crate) use entry;

/// Declares a configuration type and its runtime parameters in one place.
///
/// ```text
/// config! {
///     /// docs and derives of the type
///     pub struct Config, reached |cfg| <Option<&mut Config> in a HopperConfig>;
///     params {
///         /// (more docs of the field)
///         NUMBER ID field: type { name, unit, kind, [min, max], default, LIVE | DISARMED, doc }
///     }
///     nested {                      (each section may be left out)
///         NUMBER ID at field.inner { ... }
///     }
///     custom {
///         NUMBER ID |s| <Option<Slot> from s: &mut Config>, { ... }
///     }
///     plain {
///         /// docs
///         pub field: type = default,
///     }
/// }
/// ```
///
/// Each `params` line is a field of the type whose doc, default and entry
/// in [`TABLE`] (number on the link, name, unit, range, kind, whether it
/// may change armed) all come from that one line; `f32`, `bool`, `u8`,
/// `u16` and `u32` fields. A `nested` entry lives in a field of a `plain`
/// field (its default is written there after the plain default), a `custom`
/// one where its slot says (the plain field's default holds its default; a
/// test checks every entry reads its default). The entries are declared as
/// constants in a module `entries` (re-exported here) and listed in
/// `PARAMS`, which [`TABLE`] gathers by number.
macro_rules! config {
    (
        $(#[$smeta:meta])*
        $vis:vis struct $name:ident, reached |$rc:ident| $reach:expr;
        $(params {$(
            $(#[$fmeta:meta])*
            $fnum:literal $fid:ident $field:ident: $fty:ty {
                $fname:literal, $funit:literal, $fkind:expr, [$fmin:expr, $fmax:expr], $fdef:expr,
                $flive:ident, $fdoc:literal $(,)?
            }
        )*})?
        $(nested {$(
            $nnum:literal $nid:ident at $($npath:ident).+ { $($nspec:tt)* }
        )*})?
        $(custom {$(
            $cnum:literal $cid:ident |$cs:ident| $cslot:expr, { $($cspec:tt)* }
        )*})?
        $(plain {$(
            $(#[$pmeta:meta])*
            $pvis:vis $pfield:ident: $pty:ty = $pdef:expr,
        )*})?
    ) => {
        $(#[$smeta])*
        $vis struct $name {
            $($(
                #[doc = $fdoc]
                #[doc = ""]
                $(#[$fmeta])*
                #[doc = ""]
                #[doc = concat!(
                    "Runtime parameter `", $fname, "` (", $funit, "), in `[",
                    stringify!($fmin), ", ", stringify!($fmax), "]`, default `",
                    stringify!($fdef), "`."
                )]
                pub $field: $fty,
            )*)?
            $($(
                $(#[$pmeta])*
                $pvis $pfield: $pty,
            )*)?
        }

        impl Default for $name {
            /// The parameter table's defaults.
            fn default() -> Self {
                #[allow(unused_mut)]
                let mut s = Self {
                    $($($field: $crate::params::FromDefault::from_default(entries::$fid.default),)*)?
                    $($($pfield: $pdef,)*)?
                };
                $($(
                    s.$($npath).+ = $crate::params::FromDefault::from_default(entries::$nid.default);
                )*)?
                s
            }
        }

        /// The runtime parameters of this module's configuration, declared
        /// with its fields ([`crate::params`] re-exports them).
        pub mod entries {
            #[allow(unused_imports)]
            use super::*;
            $($(
                $crate::params::entry! {
                    $fnum $fid {
                        $fname, $funit, $fkind, [$fmin, $fmax], $fdef, $flive, $fdoc
                    },
                    |c| ({ let $rc = c; $reach }).map(|s| Slot::from(&mut s.$field))
                }
            )*)?
            $($(
                $crate::params::entry! {
                    $nnum $nid { $($nspec)* },
                    |c| ({ let $rc = c; $reach }).map(|s| Slot::from(&mut s.$($npath).+))
                }
            )*)?
            $($(
                $crate::params::entry! {
                    $cnum $cid { $($cspec)* },
                    |c| ({ let $rc = c; $reach }).and_then(|$cs| $cslot)
                }
            )*)?
        }

        /// This module's entries of [`crate::params::TABLE`].
        pub(crate) const PARAMS: &[&$crate::params::Param] =
            &[$($(&entries::$fid,)*)? $($(&entries::$nid,)*)? $($(&entries::$cid,)*)?];
    };
}
pub(crate) use config;

/// A field's value from its entry's default (`f32` in the table).
pub(crate) trait FromDefault {
    /// The field's value for `v`, which is in the entry's range (and whole
    /// for a count or flag).
    fn from_default(v: f32) -> Self;
}

impl FromDefault for f32 {
    fn from_default(v: f32) -> Self {
        v
    }
}

impl FromDefault for bool {
    fn from_default(v: f32) -> Self {
        v != 0.0
    }
}

macro_rules! from_default_count {
    ($($t:ty),*) => {$(
        impl FromDefault for $t {
            fn from_default(v: f32) -> Self {
                // Whole and within the count's range (a test checks every
                // entry reads its default).
                v as $t
            }
        }
    )*};
}
from_default_count!(u8, u16, u32);

/// Every parameter, in the order the docs list them (a parameter's index
/// here is its number on the link).
pub static TABLE: &[&Param] = &GATHERED;

/// The configuration types that declare parameters (`config!`): their
/// entries are re-exported here and gathered into [`TABLE`].
macro_rules! groups {
    ($($($module:ident)::+),* $(,)?) => {
        $(
            pub use $($module)::+::entries::*;
        )*

        /// Every group of entries.
        const GROUPS: &[&[&Param]] = &[$($($module)::+::PARAMS),*];
    };
}

groups!(
    crate::hopper,
    crate::laws::flight_pd,
    crate::laws::energy,
    crate::laws::open_torque,
    crate::laws::modified_torque,
    crate::laws::step_open,
    crate::laws::step_closed,
    crate::laws::velocity,
    crate::laws::energy_apex,
    crate::laws::shaped,
    crate::model,
    crate::estimator,
    crate::arming,
    crate::bringup,
    crate::supervisor,
    crate::debounce,
    crate::thermal,
    crate::calibration,
);

/// How many parameters there are.
// Evaluated by the compiler only: an index out of bounds is a build error.
#[allow(clippy::indexing_slicing)]
const COUNT: usize = {
    let mut n = 0;
    let mut g = 0;
    while g < GROUPS.len() {
        n += GROUPS[g].len();
        g += 1;
    }
    n
};

/// [`TABLE`] as an array: the groups' entries placed by their numbers.
static GATHERED: [&Param; COUNT] = gather(GROUPS);

/// Places each entry of `groups` at its number, refusing (at compile time)
/// a number given twice or a number past the end (with `N` the number of
/// entries, that also leaves no gap). Evaluated by the compiler only: an
/// index out of bounds or a failed check is a build error.
#[allow(clippy::indexing_slicing)]
const fn gather<const N: usize>(groups: &[&[&'static Param]]) -> [&'static Param; N] {
    let mut out = [groups[0][0]; N];
    let mut placed = [false; N];
    let mut g = 0;
    while g < groups.len() {
        let mut i = 0;
        while i < groups[g].len() {
            let p = groups[g][i];
            let n = p.number as usize;
            assert!(n < N, "a parameter's number is past the end of the table");
            assert!(!placed[n], "two parameters have the same number");
            out[n] = p;
            placed[n] = true;
            i += 1;
        }
        g += 1;
    }
    out
}

/// The controllers [`CONTROLLER`] chooses from, by name (the index is the
/// value): [`ControllerKind::ALL`]'s names.
pub const CONTROLLER_NAMES: &[&str] = <ControllerKind as strum::VariantNames>::VARIANTS;

/// The top of [`CONTROLLER`]'s range: the last registered law's index (a
/// law added to [`ControllerKind`] widens it).
pub const CONTROLLER_MAX: f32 = (CONTROLLER_NAMES.len() - 1) as f32;

/// [`CONTROLLER`]'s default: the apex-regulating energy law.
pub const CONTROLLER_DEFAULT: f32 = ControllerKind::EnergyApex as usize as f32;

/// The machine's constants (`model.*`): a configuration given whole (a
/// robot file, a saved record, a hardware-in-the-loop run) sets them
/// first, so that what follows from the model and is set apart afterwards
/// stays as set ([`HopperConfig::follow_model`]).
pub const MACHINE: &[&Param] = crate::model::PARAMS;

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

/// Where a parameter lives in a configuration.
#[allow(missing_docs)]
pub(crate) enum Slot<'a> {
    Real(&'a mut f32),
    Flag(&'a mut bool),
    U32(&'a mut u32),
    U16(&'a mut u16),
    U8(&'a mut u8),
    Controller,
    StepClosedGain(&'a mut step_closed::Gain),
    Measure(&'a mut energy_apex::EnergyMeasure),
}

macro_rules! slot_from {
    ($($t:ty => $v:ident),*) => {$(
        impl<'a> From<&'a mut $t> for Slot<'a> {
            fn from(v: &'a mut $t) -> Self {
                Slot::$v(v)
            }
        }
    )*};
}
slot_from!(f32 => Real, bool => Flag, u32 => U32, u16 => U16, u8 => U8);

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
    Ok(match (p.slot)(c).ok_or(ParamError::NotSelected(p.name))? {
        Slot::Real(v) => *v,
        Slot::Flag(b) => f32::from(u8::from(*b)),
        // Counts are checked against their (below 2^24) ranges on set, so
        // they are exact in f32.
        Slot::U32(n) => *n as f32,
        Slot::U16(n) => f32::from(*n),
        Slot::U8(n) => f32::from(*n),
        Slot::Controller => index as f32,
        Slot::StepClosedGain(g) => match g {
            step_closed::Gain::Fixed { .. } => 0.0,
            step_closed::Gain::Normalised { .. } => 1.0,
        },
        Slot::Measure(m) => match m {
            energy_apex::EnergyMeasure::Total => 0.0,
            energy_apex::EnergyMeasure::Body => 1.0,
        },
    })
}

/// Checks every parameter `cfg` holds against its entry's range (and
/// wholeness), naming the first one out of range in table order: the one
/// range check of a configuration, so a new entry is checked with no code
/// of its own. `Hopper::new` runs it on the whole configuration; each
/// part's `validate` runs it on the part in place ([`validate_part`]).
pub fn validate(cfg: &HopperConfig) -> Result<(), InvalidField> {
    check_in(&mut { *cfg })
}

/// [`validate`] for one part of a configuration, whose entries are found
/// where they live: `place` puts the part into the default configuration
/// (whose other values are the table's defaults, all in range).
pub fn validate_part(place: impl FnOnce(&mut HopperConfig)) -> Result<(), InvalidField> {
    let mut cfg = defaults();
    place(&mut cfg);
    check_in(&mut cfg)
}

/// The default configuration, built in one place in the image (not once
/// per part that [`validate_part`] checks).
#[inline(never)]
fn defaults() -> HopperConfig {
    HopperConfig::default()
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
    if MACHINE.iter().any(|m| m.number == p.number) {
        let old = cfg.model;
        write_slot(cfg, p, v)?;
        cfg.follow_model(&old);
        return Ok(());
    }
    write_slot(cfg, p, v)
}

/// Puts `v`, already checked against `p`'s range, where `p` lives in `cfg`.
fn write_slot(cfg: &mut HopperConfig, p: &Param, v: f32) -> Result<(), ParamError> {
    match (p.slot)(cfg).ok_or(ParamError::NotSelected(p.name))? {
        Slot::Real(x) => *x = v,
        Slot::Flag(b) => *b = v != 0.0,
        // Whole and within the count's range (checked above).
        Slot::U32(n) => *n = v as u32,
        Slot::U16(n) => *n = v as u16,
        Slot::U8(n) => *n = v as u8,
        Slot::Controller => {
            cfg.strategy = controller_default(v as usize).ok_or(ParamError::OutOfRange(p.name))?;
        }
        Slot::StepClosedGain(g) => {
            let fixed = matches!(g, step_closed::Gain::Fixed { .. });
            if fixed == (v == 0.0) {
                // The same choice: keep its value.
                return Ok(());
            }
            *g = if v == 0.0 {
                step_closed::Gain::Fixed {
                    kp_m_per_j: STEP_CLOSED_KP_M_PER_J.default,
                }
            } else {
                step_closed::Gain::Normalised {
                    min_compression_m: STEP_CLOSED_MIN_COMPRESSION_M.default,
                }
            };
        }
        Slot::Measure(m) => {
            *m = if v == 0.0 {
                energy_apex::EnergyMeasure::Total
            } else {
                energy_apex::EnergyMeasure::Body
            };
        }
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
mod tests {
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
        set(&mut cfg, "model.spring_stiffness_n_per_m", 15_000.0)
            .unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(cfg.supervisor.spring_rate_n_per_m, 15_000.0);
        set(&mut cfg, "supervisor.spring_rate_n_per_m", 14_200.0)
            .unwrap_or_else(|e| panic!("{e:?}"));
        set(&mut cfg, "model.spring_stiffness_n_per_m", 16_000.0)
            .unwrap_or_else(|e| panic!("{e:?}"));
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
            let owner = CONTROLLER_NAMES.iter().position(|n| {
                let prefix = match *n {
                    "open-torque" => "constant_torque",
                    "modified-torque" => "modified_torque",
                    "step-open" => "step_open",
                    "step-closed" => "step_closed",
                    "energy-apex" => "energy_apex",
                    other => other,
                };
                p.name.starts_with(&[prefix, "."].concat())
            });
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
                let put = match (p.slot)(&mut c) {
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
             Generated from `firmware/control/src/params.rs` (`hopper_control::params::TABLE`) by\n\
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
}
