//! How a runtime parameter is declared: its entry (name, unit, kind, range,
//! default, whether it may change while the motor is driven, a one-line
//! doc), the `config!` macro that declares a configuration type with its
//! entries, and where an entry lives in its own type ([`Field`]).
//!
//! This is the bottom of the parameter machinery: it knows no
//! configuration. Each configuration type declares its entries here and
//! checks them itself ([`validate_fields`]); the table of every entry
//! ([`crate::params::TABLE`]) gathers them above the configurations it
//! lists, so nothing below it imports the table.

/// A configuration field outside its documented range, named by its path
/// in the configuration (e.g. `flight.kp_a_per_rad`): the controller is
/// refused at construction rather than run with a silent 0 A.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InvalidField(pub &'static str);

/// `Ok(())` if `ok`, else the field named.
#[inline]
pub(crate) fn require(ok: bool, field: &'static str) -> Result<(), InvalidField> {
    if ok {
        Ok(())
    } else {
        Err(InvalidField(field))
    }
}

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
    /// Its number on the link: its index in [`crate::params::TABLE`].
    /// Given in the declaration, so a parameter added later (at the end)
    /// leaves every other parameter's number as it was.
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
}

impl PartialEq for Param {
    /// One parameter per number (a const check on the table).
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

/// A field that is a choice among variants with values of their own (a
/// gain that is fixed or normalised, say): its index, and the switch to
/// another variant (from that variant's defaults; the same index keeps the
/// values).
pub trait Choice {
    /// The selected variant's index among the entry's names.
    fn index(&self) -> usize;
    /// Selects variant `index` (within the entry's names).
    fn choose(&mut self, index: usize);
}

/// Where a parameter lives in a configuration.
#[allow(missing_docs)]
pub enum Slot<'a> {
    Real(&'a mut f32),
    Flag(&'a mut bool),
    U32(&'a mut u32),
    U16(&'a mut u16),
    U8(&'a mut u8),
    /// The selected controller: the strategy's variant (the table reads
    /// and switches it).
    Controller,
    /// A choice among variants of a field ([`Choice`]).
    Choice(&'a mut dyn Choice),
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

/// One entry of configuration type `C`, with where its value lives in a
/// `C` (`None` when it is absent there: a variant of a choice that lacks
/// it).
pub struct Field<C: 'static> {
    /// The entry.
    pub param: &'static Param,
    /// Its value in a `C`.
    pub slot: for<'a> fn(&'a mut C) -> Option<Slot<'a>>,
}

/// The value in `slot`, as the table's `f32`; `None` for the controller
/// choice (the table reads it from the strategy).
pub fn value_of(slot: Slot<'_>) -> Option<f32> {
    Some(match slot {
        Slot::Real(v) => *v,
        Slot::Flag(b) => f32::from(u8::from(*b)),
        // Counts are checked against their (below 2^24) ranges on set, so
        // they are exact in f32.
        Slot::U32(n) => *n as f32,
        Slot::U16(n) => f32::from(*n),
        Slot::U8(n) => f32::from(*n),
        Slot::Choice(c) => c.index() as f32,
        Slot::Controller => return None,
    })
}

/// Puts `v`, already checked against its entry, into `slot`; `false` for
/// the controller choice (the table switches it).
pub fn put(slot: Slot<'_>, v: f32) -> bool {
    match slot {
        Slot::Real(x) => *x = v,
        Slot::Flag(b) => *b = v != 0.0,
        // Whole and within the count's range (checked by the caller).
        Slot::U32(n) => *n = v as u32,
        Slot::U16(n) => *n = v as u16,
        Slot::U8(n) => *n = v as u8,
        Slot::Choice(c) => c.choose(v as usize),
        Slot::Controller => return false,
    }
    true
}

/// Checks every entry `c` holds against its range (and wholeness), naming
/// the first one out of range: each configuration type's own check of its
/// entries, in declaration order (`config!`'s `FIELDS`).
pub fn validate_fields<C: 'static>(c: &mut C, fields: &[Field<C>]) -> Result<(), InvalidField> {
    // One loop in the image for every type (the type's part is only the
    // reach into it): the constructors that check their parts stay small.
    check_each(fields.len(), &mut |i| {
        let f = fields.get(i)?;
        Some((f.param, (f.slot)(c).and_then(value_of)))
    })
}

/// Checks the `n` entries `entry` gives, each with its value (`None`:
/// not in the configuration), naming the first one out of range.
#[inline(never)]
fn check_each(
    n: usize,
    entry: &mut dyn FnMut(usize) -> Option<(&'static Param, Option<f32>)>,
) -> Result<(), InvalidField> {
    for i in 0..n {
        if let Some((p, Some(v))) = entry(i) {
            p.check(v)?;
        }
    }
    Ok(())
}

/// One parameter's entry: `NUMBER ID { name, unit, kind, [min, max],
/// default, LIVE | DISARMED, doc }`. The configuration types declare their
/// parameters with `config!`, which writes these.
macro_rules! entry {
    (
        $(#[$meta:meta])*
        $number:literal $id:ident {
            $name:literal, $unit:literal, $kind:expr, [$min:expr, $max:expr], $default:expr,
            $live:ident, $doc:literal $(,)?
        }
    ) => {
        $(#[$meta])*
        #[doc = $doc]
        pub const $id: $crate::param::Param = $crate::param::Param {
            number: $number,
            name: $name,
            unit: $unit,
            kind: {
                #[allow(unused_imports)]
                use $crate::param::Kind::{self, Count, Flag, Real};
                $kind
            },
            min: $min,
            max: $max,
            default: $default,
            live: $crate::param::$live,
            // The firmware image carries no docs (the host tools and
            // docs/parameters.md do): the link's table needs names and
            // units only, and the docs were 7 KB of flash.
            doc: if cfg!(target_os = "none") { "" } else { $doc },
        };
    };
}
pub(crate) use entry;

/// Declares a configuration type and its runtime parameters in one place.
///
/// ```text
/// config! {
///     /// docs and derives of the type
///     pub struct Config;
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
/// in the table (number on the link, name, unit, range, kind, whether it
/// may change armed) all come from that one line; `f32`, `bool`, `u8`,
/// `u16` and `u32` fields. A `nested` entry lives in a field of a `plain`
/// field (its default is written there after the plain default), a `custom`
/// one where its slot says (the plain field's default holds its default; a
/// test checks every entry reads its default). The entries are declared as
/// constants in a module `entries`, listed in `PARAMS`, and with where each
/// lives in the type in `FIELDS`; the table ([`crate::params`]) says where
/// the type lives in a whole configuration.
macro_rules! config {
    (
        $(#[$smeta:meta])*
        $vis:vis struct $name:ident;
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
                    $($($field: $crate::param::FromDefault::from_default(entries::$fid.default),)*)?
                    $($($pfield: $pdef,)*)?
                };
                $($(
                    s.$($npath).+ = $crate::param::FromDefault::from_default(entries::$nid.default);
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
                $crate::param::entry! {
                    $fnum $fid {
                        $fname, $funit, $fkind, [$fmin, $fmax], $fdef, $flive, $fdoc
                    }
                }
            )*)?
            $($(
                $crate::param::entry! { $nnum $nid { $($nspec)* } }
            )*)?
            $($(
                $crate::param::entry! { $cnum $cid { $($cspec)* } }
            )*)?
        }

        /// This module's entries of [`crate::params::TABLE`].
        pub(crate) const PARAMS: &[&$crate::param::Param] =
            &[$($(&entries::$fid,)*)? $($(&entries::$nid,)*)? $($(&entries::$cid,)*)?];

        /// This module's entries with where each lives in its configuration type.
        pub(crate) const FIELDS: &[$crate::param::Field<$name>] = &[
            $($(
                $crate::param::Field {
                    param: &entries::$fid,
                    slot: |s| Some($crate::param::Slot::from(&mut s.$field)),
                },
            )*)?
            $($(
                $crate::param::Field {
                    param: &entries::$nid,
                    slot: |s| Some($crate::param::Slot::from(&mut s.$($npath).+)),
                },
            )*)?
            $($(
                $crate::param::Field {
                    param: &entries::$cid,
                    slot: |$cs| {
                        #[allow(unused_imports)]
                        use $crate::param::Slot::{self, Flag as B, Real as R};
                        $cslot
                    },
                },
            )*)?
        ];
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
