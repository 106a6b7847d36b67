//! The leg spring's design calculator (thesis section 3.2, eqs 3.1-3.7,
//! Table 3.2): a round-wire helical compression spring, squared and ground,
//! from its stiffness, material, wire and outer diameters and free length.
//! `hopper-sim spring` prints it; `docs/design.md` compares it with the
//! thesis's worked example and Table 3.3.
//!
//! The thesis's arithmetic, as its numbers show (docs/design.md, "Spring
//! design"): the allowable static force leaves out the stress factor `K_s`
//! of eq 3.1, and the fatigue force is the force whose stress amplitude
//! and mean (eq 3.5, the spring unloading fully: `F_min = 0`) add up to
//! the allowable stress. This module computes both static forces (with and
//! without `K_s`: the thesis's 1180 N is the second) and that fatigue
//! force, and the allowable stroke from the fatigue force.

use serde::Serialize;

/// A spring wire (Table 3.2's tensile-strength fit `S_ut = A / d^m`, `d` in
/// inches and `A` in kpsi, after Shigley's Table 10-4, the thesis's [26];
/// the shear modulus for wires over 0.125 in from Shigley's Table 10-5).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Material {
    /// Name on the command line.
    pub name: &'static str,
    /// ASTM number.
    pub astm: &'static str,
    /// Exponent `m` of the strength fit.
    pub exponent_m: f64,
    /// Intercept `A` of the strength fit, kpsi.
    pub a_kpsi: f64,
    /// Shear modulus `G`, Pa.
    pub shear_modulus_pa: f64,
}

/// Steel's density, kg/m^3 (the spring's mass).
pub const STEEL_DENSITY_KG_M3: f64 = 7850.0;
/// One kpsi in Pa.
const KPSI_PA: f64 = 6.894_757e6;
/// One inch in m.
const INCH_M: f64 = 0.0254;

/// Table 3.2's materials.
pub const MATERIALS: [Material; 5] = [
    Material {
        name: "music-wire",
        astm: "A228",
        exponent_m: 0.163,
        a_kpsi: 186.0,
        shear_modulus_pa: 80.0e9,
    },
    Material {
        name: "oil-tempered",
        astm: "A229",
        exponent_m: 0.193,
        a_kpsi: 146.0,
        shear_modulus_pa: 77.2e9,
    },
    Material {
        name: "hard-drawn",
        astm: "A227",
        exponent_m: 0.201,
        a_kpsi: 137.0,
        shear_modulus_pa: 78.6e9,
    },
    Material {
        name: "chrome-vanadium",
        astm: "A232",
        exponent_m: 0.155,
        a_kpsi: 173.0,
        shear_modulus_pa: 77.2e9,
    },
    Material {
        name: "chrome-silicon",
        astm: "A401",
        exponent_m: 0.091,
        a_kpsi: 218.0,
        shear_modulus_pa: 77.2e9,
    },
];

impl Material {
    /// By its command-line name.
    pub fn by_name(name: &str) -> Option<Material> {
        MATERIALS.iter().copied().find(|m| m.name == name)
    }

    /// The wire's tensile strength `S_ut = A / d^m` (eq 3.7), Pa.
    pub fn tensile_strength_pa(&self, wire_m: f64) -> f64 {
        self.a_kpsi * KPSI_PA / (wire_m / INCH_M).powf(self.exponent_m)
    }
}

/// What the spring must be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringSpec {
    /// Rate `k`, N/m.
    pub stiffness_n_per_m: f64,
    /// The wire.
    pub material: Material,
    /// Wire diameter `d`, m.
    pub wire_m: f64,
    /// Outer diameter `D_o`, m.
    pub outer_m: f64,
    /// Free length `L_0`, m.
    pub free_length_m: f64,
    /// The longest solid length allowed, m (None: no limit).
    pub max_solid_m: Option<f64>,
    /// The shortest stroke required, m (None: no requirement).
    pub min_stroke_m: Option<f64>,
}

/// The design, every length in m, force in N, stress in Pa.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SpringDesign {
    /// Material name.
    pub material: &'static str,
    /// Wire diameter `d`, m.
    pub wire_m: f64,
    /// Mean coil diameter `D = D_o - d`, m.
    pub mean_diameter_m: f64,
    /// Spring index `C = D / d` (eq 3.2).
    pub index: f64,
    /// Shear-stress factor `K_s = (2C + 1) / 2C` (eq 3.2).
    pub ks: f64,
    /// Bergstraesser factor `K_B = (4C + 2) / (4C - 3)` (eq 3.6).
    pub kb: f64,
    /// Active coils for the rate exactly, `d^4 G / (8 D^3 k)` (eq 3.3).
    pub active_coils_exact: f64,
    /// Active coils, rounded up to whole coils.
    pub active_coils: u32,
    /// Total coils `N_t = N + 2` (two end coils, squared and ground).
    pub total_coils: u32,
    /// The rate with the whole coils (eq 3.3), N/m.
    pub rate_n_per_m: f64,
    /// Pitch `p = (L_0 - 2d) / N`, m.
    pub pitch_m: f64,
    /// Free length `L_0`, m.
    pub free_length_m: f64,
    /// Solid length `L_s = d N_t`, m.
    pub solid_length_m: f64,
    /// Stroke to solid `L_0 - L_s`, m.
    pub total_stroke_m: f64,
    /// Tensile strength `S_ut` (eq 3.7), Pa.
    pub tensile_strength_pa: f64,
    /// Allowable shear stress `S_ut / 2`, Pa.
    pub allowable_stress_pa: f64,
    /// The force at the allowable stress by eq 3.1 with `K_s`, N.
    pub static_force_n: f64,
    /// The same without `K_s` (the thesis's arithmetic), N.
    pub static_force_without_ks_n: f64,
    /// The force whose amplitude and mean stresses (eq 3.5, from 0) add to
    /// the allowable stress, N.
    pub fatigue_force_n: f64,
    /// The stroke at the fatigue force (no further than solid), m.
    pub allowable_stroke_m: f64,
    /// Mass of the `N_t` coils of wire, kg.
    pub mass_kg: f64,
    /// Energy stored at the allowable stroke per kg of spring, J/kg.
    pub energy_per_kg_j: f64,
    /// Whether the solid length and the stroke meet the limits asked.
    pub meets_limits: bool,
}

/// Why a spring cannot be designed.
#[derive(Clone, Debug, PartialEq)]
pub enum SpringError {
    /// A dimension is not a positive finite number (its name).
    NotPositive(&'static str),
    /// The wire is as thick as the coil: no coil (index below 1.5).
    IndexTooSmall(f64),
    /// More than 10,000 active coils: the wire is far too thin for the rate.
    TooManyCoils(f64),
    /// The spring is solid before it is free: `d N_t >= L_0`.
    NoStroke {
        /// Solid length, m.
        solid_m: f64,
    },
}

impl core::fmt::Display for SpringError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SpringError::NotPositive(name) => write!(f, "{name} must be a positive number"),
            SpringError::IndexTooSmall(c) => write!(
                f,
                "spring index D/d = {c:.2}: the wire is too thick for the outer diameter (at least 1.5)"
            ),
            SpringError::TooManyCoils(n) => write!(
                f,
                "{n:.0} active coils: the wire is far too thin (or the rate far too low) for a spring"
            ),
            SpringError::NoStroke { solid_m } => write!(
                f,
                "the solid length {:.1} mm is not shorter than the free length: no stroke",
                solid_m * 1e3
            ),
        }
    }
}

impl std::error::Error for SpringError {}

/// The design for `s`.
pub fn design(s: &SpringSpec) -> Result<SpringDesign, SpringError> {
    for (name, v) in [
        ("stiffness", s.stiffness_n_per_m),
        ("wire diameter", s.wire_m),
        ("outer diameter", s.outer_m),
        ("free length", s.free_length_m),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(SpringError::NotPositive(name));
        }
    }
    let d = s.wire_m;
    let mean = s.outer_m - d;
    let c = mean / d;
    if c.is_nan() || c < 1.5 {
        return Err(SpringError::IndexTooSmall(c));
    }
    let ks = (2.0 * c + 1.0) / (2.0 * c);
    let kb = (4.0 * c + 2.0) / (4.0 * c - 3.0);
    let g = s.material.shear_modulus_pa;
    let rate_per_coil = d.powi(4) * g / (8.0 * mean.powi(3));
    let exact = rate_per_coil / s.stiffness_n_per_m;
    if exact.is_nan() || exact > 10_000.0 {
        return Err(SpringError::TooManyCoils(exact));
    }
    // Whole coils, at least one; rounding up leaves the rate at or below
    // the one asked.
    let n = exact.ceil().max(1.0) as u32;
    let nt = n + 2;
    let rate = rate_per_coil / f64::from(n);
    let solid = d * f64::from(nt);
    let total_stroke = s.free_length_m - solid;
    if total_stroke <= 0.0 {
        return Err(SpringError::NoStroke { solid_m: solid });
    }
    let pitch = (s.free_length_m - 2.0 * d) / f64::from(n);
    let sut = s.material.tensile_strength_pa(d);
    let tau_all = 0.5 * sut;
    // Eq 3.1 solved for the force at the allowable stress.
    let force_at = |factor: f64| tau_all * std::f64::consts::PI * d.powi(3) / (8.0 * factor * mean);
    let static_force = force_at(ks);
    let static_force_without_ks = force_at(1.0);
    // Eq 3.4-3.5 with F_min = 0: F_a = F_m = F/2, and tau_a + tau_m =
    // (K_B + K_s) 4 F D / (pi d^3) at the allowable stress.
    let fatigue_force = force_at(0.5 * (kb + ks));
    let allowable_stroke = (fatigue_force / rate).min(total_stroke);
    let wire_length = std::f64::consts::PI * mean * f64::from(nt);
    let mass = STEEL_DENSITY_KG_M3 * std::f64::consts::PI * d * d / 4.0 * wire_length;
    let energy = 0.5 * rate * allowable_stroke * allowable_stroke;
    let meets_limits = s.max_solid_m.is_none_or(|m| solid <= m)
        && s.min_stroke_m.is_none_or(|m| allowable_stroke >= m);
    Ok(SpringDesign {
        material: s.material.name,
        wire_m: d,
        mean_diameter_m: mean,
        index: c,
        ks,
        kb,
        active_coils_exact: exact,
        active_coils: n,
        total_coils: nt,
        rate_n_per_m: rate,
        pitch_m: pitch,
        free_length_m: s.free_length_m,
        solid_length_m: solid,
        total_stroke_m: total_stroke,
        tensile_strength_pa: sut,
        allowable_stress_pa: tau_all,
        static_force_n: static_force,
        static_force_without_ks_n: static_force_without_ks,
        fatigue_force_n: fatigue_force,
        allowable_stroke_m: allowable_stroke,
        mass_kg: mass,
        energy_per_kg_j: energy / mass,
        meets_limits,
    })
}

impl SpringDesign {
    /// The design as lines for a terminal.
    pub fn lines(&self) -> Vec<String> {
        let mm = |m: f64| m * 1e3;
        vec![
            format!(
                "wire: {} {:.2} mm, mean coil diameter {:.2} mm, index C = {:.2}, K_s = {:.3}, K_B = {:.3}",
                self.material,
                mm(self.wire_m),
                mm(self.mean_diameter_m),
                self.index,
                self.ks,
                self.kb
            ),
            format!(
                "coils: {:.3} active for the rate exactly -> N = {} active, N_t = {} total; rate {:.0} N/m",
                self.active_coils_exact, self.active_coils, self.total_coils, self.rate_n_per_m
            ),
            format!(
                "lengths: pitch {:.2} mm, free {:.1} mm, solid {:.2} mm, stroke to solid {:.1} mm",
                mm(self.pitch_m),
                mm(self.free_length_m),
                mm(self.solid_length_m),
                mm(self.total_stroke_m)
            ),
            format!(
                "strength: S_ut {:.0} MPa, allowable shear stress {:.1} MPa",
                self.tensile_strength_pa / 1e6,
                self.allowable_stress_pa / 1e6
            ),
            format!(
                "allowable force: static {:.0} N (eq 3.1 with K_s; {:.0} N without, as the thesis), fatigue {:.0} N (eq 3.5 from 0)",
                self.static_force_n, self.static_force_without_ks_n, self.fatigue_force_n
            ),
            format!(
                "allowable stroke: {:.1} mm; mass {:.0} g; {:.0} J/kg stored at that stroke",
                mm(self.allowable_stroke_m),
                self.mass_kg * 1e3,
                self.energy_per_kg_j
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn thesis(k: f64, material: &str, wire_mm: f64) -> SpringDesign {
        let spec = SpringSpec {
            stiffness_n_per_m: k,
            material: Material::by_name(material).unwrap_or(MATERIALS[0]),
            wire_m: wire_mm * 1e-3,
            outer_m: 0.052,
            free_length_m: 0.235,
            max_solid_m: None,
            min_stroke_m: Some(0.1),
        };
        design(&spec).unwrap_or_else(|e| panic!("{e}"))
    }

    fn near(x: f64, want: f64, tol: f64) -> bool {
        (x - want).abs() <= tol
    }

    /// Section 3.2's worked example: k = 10 kN/m, music wire 5.53 mm, 52 mm
    /// outside, 235 mm free.
    #[test]
    fn the_worked_example() {
        let s = thesis(10_000.0, "music-wire", 5.53);
        assert!(near(s.mean_diameter_m, 46.47e-3, 1e-5), "{s:?}");
        assert!(near(s.index, 8.4, 0.01), "{s:?}");
        assert!(near(s.kb, 1.16, 0.005), "{s:?}");
        // The thesis's 9.744 needs G = 83.6 GPa; Shigley's 80.0 GPa gives
        // 9.32: both round up to 10.
        assert!(near(s.active_coils_exact, 9.32, 0.01), "{s:?}");
        assert_eq!((s.active_coils, s.total_coils), (10, 12));
        assert!(near(s.pitch_m, 22.4e-3, 0.05e-3), "{s:?}");
        assert!(near(s.solid_length_m, 66.36e-3, 0.01e-3), "{s:?}");
        assert!(near(s.total_stroke_m, 168.6e-3, 0.1e-3), "{s:?}");
        // S_ut 1650 MPa (1642.7 behind its 821.36 MPa).
        assert!(near(s.tensile_strength_pa, 1644e6, 2e6), "{s:?}");
        // 1180 N within 1%; 1070 N and its stroke at 10 kN/m, 107 mm,
        // within 2% (the thesis rounded K_s to 1.05 and K_B to 1.16, and
        // took d = 0.218 in).
        assert!(near(s.static_force_without_ks_n, 1180.0, 11.8), "{s:?}");
        assert!(near(s.fatigue_force_n, 1070.0, 21.4), "{s:?}");
        assert!(near(s.fatigue_force_n / 10_000.0, 0.107, 2.14e-3), "{s:?}");
        // At the rate of its whole coils the stroke is longer: 113 mm.
        assert!(near(s.allowable_stroke_m, 0.1134, 0.5e-3), "{s:?}");
        // With K_s as eq 3.1 writes it: 1108 N.
        assert!(near(s.static_force_n, 1108.0, 2.0), "{s:?}");
        assert!(s.meets_limits);
    }

    /// Table 3.3's columns: the 10 kN/m music-wire spring and the 20 kN/m
    /// chrome-vanadium one.
    #[test]
    fn table_3_3() {
        let a = thesis(10_000.0, "music-wire", 5.53);
        let b = thesis(20_000.0, "chrome-vanadium", 7.06);
        // Pitch 22.4 and 15.8 mm: 10 and 14 active coils.
        assert!(near(a.pitch_m, 22.4e-3, 0.05e-3));
        assert_eq!(b.active_coils, 14, "{b:?}");
        assert!(near(b.pitch_m, 15.8e-3, 0.05e-3), "{b:?}");
        // Weights 315 and 670 g: the N_t coils of wire within 5%.
        assert!(near(a.mass_kg, 0.315, 0.05 * 0.315), "{a:?}");
        assert!(near(b.mass_kg, 0.670, 0.05 * 0.670), "{b:?}");
        // Stroke to solid 168.6 mm; the chrome-vanadium's 118 mm is its
        // d N_t = 113 mm solid length off by 5 mm (docs/design.md).
        assert!(near(a.total_stroke_m, 168.6e-3, 0.1e-3));
        assert!(near(b.total_stroke_m, 122.0e-3, 0.1e-3), "{b:?}");
        // Energy per kg, 180 J/kg at 107 mm: within 5%.
        assert!(near(a.energy_per_kg_j, 180.0, 9.0), "{a:?}");
    }

    #[test]
    fn bad_dimensions_are_refused_by_name() {
        let mut s = SpringSpec {
            stiffness_n_per_m: 10_000.0,
            material: MATERIALS[0],
            wire_m: 5.53e-3,
            outer_m: 0.052,
            free_length_m: 0.235,
            max_solid_m: None,
            min_stroke_m: None,
        };
        s.wire_m = f64::NAN;
        assert_eq!(design(&s), Err(SpringError::NotPositive("wire diameter")));
        s.wire_m = 0.03;
        assert!(matches!(design(&s), Err(SpringError::IndexTooSmall(_))));
        s.wire_m = 5.53e-3;
        s.stiffness_n_per_m = 1e-5;
        assert!(matches!(design(&s), Err(SpringError::TooManyCoils(_))));
        s.stiffness_n_per_m = 10_000.0;
        s.free_length_m = 0.05;
        assert!(matches!(design(&s), Err(SpringError::NoStroke { .. })));
        assert!(Material::by_name("unobtainium").is_none());
    }
}
