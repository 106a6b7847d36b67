//! The firmware's types on the wire and back: refusals, hops, records,
//! reports, pacing, parameter descriptions.

use super::*;

/// What paces the periods, on the wire.
pub(crate) fn pacing(p: hopper_control::runner::Pacing) -> hopper_protocol::vocab::Pacing {
    use hopper_control::runner::Pacing as P;
    match p {
        P::Trigger { .. } => hopper_protocol::vocab::Pacing::Trigger,
        P::NoClock => hopper_protocol::vocab::Pacing::NoClock,
        P::Host => hopper_protocol::vocab::Pacing::Host,
        P::Sustained => hopper_protocol::vocab::Pacing::Sustained,
    }
}

/// How a period was late, on the wire.
pub(crate) fn late_cause(
    c: hopper_control::runner::LateCause,
) -> hopper_protocol::vocab::LateCause {
    use hopper_control::runner::LateCause as C;
    match c {
        C::Deadline => hopper_protocol::vocab::LateCause::Deadline,
        C::Start => hopper_protocol::vocab::LateCause::Start,
    }
}

/// A parameter's kind and owner ([`Request::ParamMeta`]). Finding the
/// owner tries the controllers' configurations: link-task work, answered
/// here without the control period.
pub fn param_meta(name: &str) -> Response {
    use hopper_protocol::vocab::ParamKind;
    let Some((index, p)) = params::TABLE
        .iter()
        .enumerate()
        .find(|(_, p)| p.name == name)
    else {
        return refused(Refusal::UnknownParameter);
    };
    let (kind, choices) = match p.kind {
        params::Kind::Real => (ParamKind::Real, 0),
        params::Kind::Count => (ParamKind::Count, 0),
        params::Kind::Flag => (ParamKind::Flag, 0),
        params::Kind::Choice(names) => (ParamKind::Choice, names.len()),
    };
    let owner = params::owner(p);
    let index_of = |q: &params::Param| Some(usize::from(q.number));
    Response::ParamMeta(hopper_protocol::ParamMeta {
        index: index as u16,
        kind: kind.code(),
        choices: choices as u8,
        controller: owner.map(|o| o.controller as u8),
        needs: owner
            .and_then(|o| o.choice)
            .and_then(|(q, v)| Some((index_of(q)? as u16, v as u8))),
    })
}

/// The name of value `value` of choice parameter `name`
/// ([`Request::ParamChoice`]).
pub fn param_choice(name: &str, value: u8) -> Response {
    match params::find(name).map(|p| p.kind) {
        None => refused(Refusal::UnknownParameter),
        Some(params::Kind::Choice(names)) => match names.get(usize::from(value)) {
            Some(n) => {
                let mut out = hopper_protocol::Name::new();
                // Every choice's name is far shorter than a parameter's.
                let _ = out.push_str(n);
                Response::Name(out)
            }
            None => refused(Refusal::OutOfRange),
        },
        Some(_) => refused(Refusal::OutOfRange),
    }
}

/// A refusal's answer.
pub(crate) fn refused(r: Refusal) -> Response {
    Response::Refused(r.into())
}

/// An arm refusal's wire reason (the same name: a test checks).
pub fn arm_refusal(r: ArmRefusal) -> Refusal {
    use ArmRefusal as A;
    match r {
        A::Faulted => Refusal::Faulted,
        A::EstopPressed => Refusal::EstopPressed,
        A::LinkDown => Refusal::LinkDown,
        A::SensorsImplausible => Refusal::SensorsImplausible,
        A::NutNotHome => Refusal::NutNotHome,
        A::Moving => Refusal::Moving,
        A::ClockFallback => Refusal::ClockFallback,
        A::BrownOutResetOff => Refusal::BrownOutResetOff,
        A::CrystalMismatch => Refusal::CrystalMismatch,
        A::NotCalibrated => Refusal::NotCalibrated,
        A::Calibrating => Refusal::Calibrating,
        A::DirectionReversed => Refusal::DirectionReversed,
        A::NotHomed => Refusal::NotHomed,
    }
}

/// A bring-up routine's refusal on the wire (the same name: a test checks).
pub fn cal_refusal(r: CalRefusal) -> Refusal {
    match r {
        CalRefusal::Armed => Refusal::DisarmFirst,
        CalRefusal::EstopPressed => Refusal::EstopPressed,
        CalRefusal::Busy => Refusal::Busy,
        CalRefusal::Unknown => Refusal::UnknownRoutine,
        CalRefusal::Duration => Refusal::BadDuration,
        CalRefusal::Faulted => Refusal::Faulted,
        CalRefusal::LinkDown => Refusal::LinkDown,
        CalRefusal::DirectionFirst => Refusal::CheckDirectionFirst,
        CalRefusal::HomeFirst => Refusal::HomeFirst,
        CalRefusal::TareFirst => Refusal::TareFirst,
        CalRefusal::LegLoaded => Refusal::LegLoaded,
        CalRefusal::NotOnGround => Refusal::NotOnGround,
        CalRefusal::NoMeasurementYet => Refusal::NoMeasurementYet,
    }
}

/// Why a parameter set was refused, on the wire.
pub fn set_refusal(e: &SetError) -> Refusal {
    use hopper_control::params::ParamError as P;
    match e {
        SetError::Param(P::Unknown) => Refusal::UnknownParameter,
        SetError::Param(P::OutOfRange(_)) => Refusal::OutOfRange,
        SetError::Param(P::NotSelected(_)) => Refusal::ControllerNotSelected,
        SetError::WhileArmed(_) => Refusal::DisarmFirst,
        SetError::Calibrating => Refusal::Calibrating,
        SetError::Config(_) => Refusal::InvalidConfiguration,
        // The configuration moved under the change: asking again works.
        SetError::Stale => Refusal::Busy,
    }
}

/// The wire form of a hop's ledger.
pub fn wire_hop(h: &hopper_control::telemetry::HopLedger) -> Hop {
    Hop {
        hop: h.hop,
        apex_height_m: h.apex_height_m,
        energy_at_touchdown_j: h.energy_at_touchdown_j,
        energy_at_liftoff_j: h.energy_at_liftoff_j,
        stance_work_j: h.stance_work_j,
        stance_duration_s: h.stance_duration_s,
        peak_current_a: h.peak_current_a,
        peak_stroke_m: h.peak_stroke_m,
        copper_loss_j: h.copper_loss_j,
        stance_copper_loss_j: h.stance_copper_loss_j,
    }
}

/// A hop's ledger from the wire (the inverse of [`wire_hop`]).
pub fn ledger_from_wire(h: &Hop) -> hopper_control::telemetry::HopLedger {
    hopper_control::telemetry::HopLedger {
        hop: h.hop,
        apex_height_m: h.apex_height_m,
        energy_at_touchdown_j: h.energy_at_touchdown_j,
        energy_at_liftoff_j: h.energy_at_liftoff_j,
        stance_work_j: h.stance_work_j,
        stance_duration_s: h.stance_duration_s,
        peak_current_a: h.peak_current_a,
        peak_stroke_m: h.peak_stroke_m,
        copper_loss_j: h.copper_loss_j,
        stance_copper_loss_j: h.stance_copper_loss_j,
    }
}

/// The wire form of the arming state.
pub fn arm_state(s: RunnerArmState) -> ArmState {
    match s {
        RunnerArmState::Armed => ArmState::Armed,
        RunnerArmState::Disarmed(r) => ArmState::Disarmed(
            DISARM_REASONS
                .iter()
                .position(|x| *x == r)
                .and_then(|i| u8::try_from(i).ok())
                .unwrap_or(u8::MAX),
        ),
    }
}

/// A disarm reason from its wire code.
pub fn disarm_reason(code: u8) -> Option<DisarmReason> {
    DISARM_REASONS.get(usize::from(code)).copied()
}

/// The wire form of a step record.
pub fn wire_record(seq: u32, r: &StepRecord) -> Telemetry {
    Telemetry {
        seq,
        step: r.step,
        phase: r.phase,
        armed: r.armed,
        faults: r.faults,
        body_height_m: r.body_height_m,
        nut_position_m: r.nut_position_m,
        spring_force_n: r.spring_force_n,
        energy_j: r.energy_j,
        command_a: r.command_a,
    }
}

/// A routine's report on the wire (codes for the routine and its state).
pub(crate) fn calibration_info(
    r: &hopper_control::bringup::CalibrationReport,
) -> hopper_protocol::CalibrationInfo {
    hopper_protocol::CalibrationInfo {
        routine: r.routine as u8,
        state: r.state as u8,
        samples: r.samples,
        loadcell_mean_code: r.loadcell_mean_code,
        loadcell_std_code: r.loadcell_std_code,
        pot_mean_code: r.pot_mean_code,
        pot_std_code: r.pot_std_code,
        motor_span_counts: r.motor_span_counts,
        height_span_counts: r.height_span_counts,
        loadcell_offset_code: r.loadcell_offset_code,
        pot_offset_code: r.pot_offset_code,
    }
}

/// The motor-driving and height routines' results on the wire.
pub(crate) fn bringup_info(
    r: &hopper_control::bringup::BringupReport,
) -> hopper_protocol::BringupResults {
    hopper_protocol::BringupResults {
        routine: r.routine as u8,
        state: r.state as u8,
        nut_travel_m: r.nut_travel_m,
        force_change_n: r.force_change_n,
        nut_offset_m: r.nut_offset_m,
        spring_rate_n_per_m: r.spring_rate_n_per_m,
        spring_intercept_n: r.spring_intercept_n,
        fit_rms_n: r.fit_rms_n,
        fit_points: r.fit_points,
        fit_span_m: r.fit_span_m,
        height_offset_m: r.height_offset_m,
        peak_current_a: r.peak_current_a,
    }
}

/// The last weighing on the wire.
pub(crate) fn weighing_info(
    r: &hopper_control::bringup::WeighingReport,
) -> hopper_protocol::WeighingInfo {
    hopper_protocol::WeighingInfo {
        state: r.state as u8,
        weight_n: r.weight_n,
        configured_weight_n: r.configured_weight_n,
        friction_n: r.friction_n,
        body_rise_m: r.body_rise_m,
    }
}

#[cfg(test)]
mod vocabulary_tests {
    //! The firmware's own types and the wire's vocabulary
    //! (`hopper_protocol::vocab`) name every code alike: the host prints
    //! the protocol's names for the codes the robot sends.
    use super::{disarm_reason, DISARM_REASONS};
    use hopper_control::{boot, bringup, persist, supervisor};
    use hopper_protocol::vocab;

    /// The robot describes its parameters: kind, choices and owner, with
    /// the owner's choice by table index.
    #[test]
    fn parameters_are_described() {
        use hopper_protocol::{vocab::ParamKind, ParamMeta, Response};
        let index = |n: &str| {
            hopper_control::params::TABLE
                .iter()
                .position(|p| p.name == n)
        };
        let controller = |n: &str| {
            hopper_control::params::CONTROLLER_NAMES
                .iter()
                .position(|c| *c == n)
                .map(|i| i as u8)
        };
        let Response::ParamMeta(m) = super::param_meta("step_closed.min_compression_m") else {
            panic!("no description")
        };
        assert_eq!(
            m,
            ParamMeta {
                index: index("step_closed.min_compression_m").unwrap_or(9999) as u16,
                kind: ParamKind::Real.code(),
                choices: 0,
                controller: controller("step-closed"),
                needs: index("step_closed.gain").map(|i| (i as u16, 1)),
            }
        );
        let Response::ParamMeta(m) = super::param_meta("controller") else {
            panic!("no description")
        };
        assert_eq!((m.kind, m.controller), (ParamKind::Choice.code(), None));
        assert_eq!(
            usize::from(m.choices),
            hopper_control::params::CONTROLLER_NAMES.len()
        );
        let Response::Name(n) = super::param_choice("controller", 8) else {
            panic!("no name")
        };
        assert_eq!(n.as_str(), "shaped");
        for refused in [
            super::param_meta("no.such"),
            super::param_choice("controller", 200),
            super::param_choice("target_apex_m", 0),
        ] {
            assert!(matches!(refused, Response::Refused(_)), "{refused:?}");
        }
    }

    /// Every refusal the firmware names goes on the wire under that name;
    /// a parameter's refusals under the names the docs list.
    #[test]
    fn refusals_keep_their_names() {
        use strum::VariantArray;
        for &r in hopper_control::arming::ArmRefusal::VARIANTS {
            assert_eq!(super::arm_refusal(r).name(), r.name());
        }
        for &r in bringup::CalRefusal::VARIANTS {
            assert_eq!(super::cal_refusal(r).name(), r.name());
        }
        use hopper_control::params::ParamError as P;
        use hopper_control::runner::SetError as S;
        for (e, name) in [
            (S::Param(P::Unknown), "unknown-parameter"),
            (S::Param(P::OutOfRange("x")), "out-of-range"),
            (S::Param(P::NotSelected("x")), "controller-not-selected"),
            (S::WhileArmed("x"), "disarm-first"),
            (S::Calibrating, "calibrating"),
            (S::Stale, "busy"),
        ] {
            assert_eq!(super::set_refusal(&e).name(), name);
        }
    }

    #[test]
    fn every_code_has_the_same_name_on_both_ends() {
        assert_eq!(supervisor::Fault::ALL.len(), vocab::Fault::ALL.len());
        for &f in supervisor::Fault::ALL {
            let w = vocab::Fault::from_code(f as u8).expect("a wire fault for every fault");
            assert_eq!((w.name(), w.bit()), (f.name(), f.bit()));
        }
        assert_eq!(DISARM_REASONS.len(), vocab::DisarmReason::ALL.len());
        for (code, r) in DISARM_REASONS.iter().enumerate() {
            let w = vocab::DisarmReason::from_code(code as u8).expect("a wire reason");
            assert_eq!(w.name(), r.name());
            assert_eq!(disarm_reason(code as u8), Some(*r));
        }
        assert_eq!(boot::ResetCause::ALL.len(), vocab::ResetCause::ALL.len());
        for &c in boot::ResetCause::ALL {
            let w = vocab::ResetCause::from_code(c as u8).expect("a wire cause");
            assert_eq!(w.name(), c.name());
        }
        assert_eq!(bringup::Routine::ALL.len(), vocab::Routine::ALL.len());
        for &r in bringup::Routine::ALL {
            let w = vocab::Routine::from_code(r as u8).expect("a wire routine");
            assert_eq!(w.name(), r.name());
            assert_eq!(w.drives_motor(), r.drives_motor());
        }
        assert_eq!(bringup::CalState::ALL.len(), vocab::CalState::ALL.len());
        for &c in bringup::CalState::ALL {
            assert!(vocab::CalState::from_code(c as u8).is_some(), "{c:?}");
        }
        for e in [
            persist::LoadError::NotARecord,
            persist::LoadError::Version(0),
            persist::LoadError::Crc,
            persist::LoadError::UnknownEntry(0),
            persist::LoadError::Refused(""),
        ] {
            let w = vocab::LoadError::from_code(e.code()).expect("a wire load error");
            assert_eq!(w.name(), e.name());
        }
    }
}
