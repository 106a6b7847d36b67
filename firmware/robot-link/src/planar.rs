//! The planar machine's end of the host link: arming through the link,
//! both amplifiers gated by it, and the machine's telemetry
//! ([`RobotMsg::Planar`]), so that `hopper-link` and its cockpit run the
//! planar machine as they run the vertical one.
//!
//! The planar robot answers what it has: the handshake, its state
//! ([`Request::Status`], [`Request::Timing`], the hotter winding's
//! [`Request::Thermal`]), arm, disarm and fault reset, the telemetry's
//! rate, and the simulated e-stop and hoist. It has no parameter table
//! (the machine is its robot file), no bring-up routine and no capture:
//! those are refused, [`Refusal::NotThisMachine`] (a parameter,
//! [`Refusal::UnknownParameter`]).
//!
//! The same [`Arming`] as the vertical hopper's decides: disarmed at boot,
//! armed only on request with the link alive, no latched fault, the
//! e-stop released, the readings finite, the leg's nut home and still and
//! the body still; disarmed by a request, the e-stop (its press latched
//! until released and reset), a fault the guard latches (the pitch, the
//! leg's angle, a fall, a winding's trip) or link loss, in the same
//! period, before its output. A request that acts is remembered by its
//! id, so that a host's retry is answered again, never carried out
//! twice. Disarmed, both amplifiers get 0 A and their enables are off;
//! the estimator and the controller keep running, so the readings can be
//! watched.
//!
//! One type does the two halves the vertical hopper splits between the
//! control interrupt and the link task ([`crate::ControlPort`],
//! [`crate::Endpoint`]): the simulator runs it between two periods. A
//! board would split it the same way.

use crate::endpoint::{remember, send, send_hello, Memo, Memos};
use crate::{refused, Tx};
use hopper_control::arming::{ArmEvent, ArmInput, ArmState, Arming, ArmingConfig};
use hopper_control::param::InvalidField;
use hopper_control::planar::estimator::PlanarReadings;
use hopper_control::planar::guard::PlanarFault;
use hopper_control::planar::period::{LegDrive, PlanarPeriod};
use hopper_control::planar::{PlanarCommand, PlanarEstimate};
use hopper_control::supervisor::{Fault, Faults};
use hopper_protocol::vocab::{self, Refusal};
use hopper_protocol::{
    Decoder, HostMsg, PlanarTelemetry, Request, Response, RobotMsg, Status, ThermalStatus,
    TimingStats,
};

/// What the simulated machine is asked to do with its body
/// ([`Request::SimulateMount`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mount {
    /// Hold the body upright, the toe `toe_m` above the ground, until
    /// armed.
    Hoist {
        /// The toe's height above the ground, m.
        toe_m: f32,
    },
    /// Let go of it.
    Release,
}

/// A request decided by the next period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    Arm,
    Disarm,
    Reset,
}

/// What one period did, for the machine's amplifiers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// The command the amplifiers are told (zero unless armed).
    pub cmd: PlanarCommand,
    /// Both amplifiers enabled.
    pub enabled: bool,
    /// The period armed the machine and it stays armed (a held body is
    /// let go).
    pub armed_now: bool,
}

/// The planar machine's end of the link (module docs).
#[derive(Debug, Clone)]
pub struct PlanarPort {
    rx: Decoder,
    arming: Arming,
    period_s: f32,
    /// The simulator's robot: the e-stop and the hoist are simulated.
    simulated: bool,
    /// The e-stop input now, and whether its press is latched (cleared by
    /// a reset once released).
    estop_pressed: bool,
    estop_latched: bool,
    pending: Option<(u16, Pending)>,
    /// The requests that act, by id: a host's retry is answered from
    /// here, never carried out twice.
    memo: Memos,
    mount: Option<Mount>,
    /// Telemetry every this many periods (0: off), and the count since.
    every: u16,
    since: u16,
    seq: u32,
    dropped: u32,
    periods: u32,
    /// The last period's telemetry, what the state answers read.
    last: PlanarTelemetry,
    /// The last apex's toe height, m (NaN before the first).
    last_apex_m: f32,
    /// The hotter winding's estimate, as the last period left it.
    thermal: ThermalStatus,
    /// What the guard had latched at the last period.
    fault_latched: Option<PlanarFault>,
}

/// The posture's faults (the pitch, the leg's angle, a fall) have no bit
/// among the vertical supervisor's: they take the one it leaves free, for
/// the arming, which only asks whether any is latched.
const POSTURE_BIT: u16 = 1 << 15;

/// The guard's latch in [`Status::faults`]: the vertical supervisor's
/// bit of the same meaning, where it has one (the posture's faults are
/// named by [`PlanarTelemetry::fault`]).
fn status_faults(fault: Option<PlanarFault>) -> u16 {
    match fault {
        Some(PlanarFault::NonFinite) => Fault::SensorNonFinite.bit(),
        Some(PlanarFault::HipOvertemperature | PlanarFault::LegOvertemperature) => {
            Fault::Overtemperature.bit()
        }
        _ => 0,
    }
}

/// The guard's latch on the wire (0: nothing).
pub fn planar_fault(fault: Option<PlanarFault>) -> u8 {
    let f = match fault {
        None => return 0,
        Some(PlanarFault::NonFinite) => vocab::PlanarFault::Nonfinite,
        Some(PlanarFault::Pitch) => vocab::PlanarFault::Pitch,
        Some(PlanarFault::LegAngle) => vocab::PlanarFault::LegAngle,
        Some(PlanarFault::Fall) => vocab::PlanarFault::Fall,
        Some(PlanarFault::HipOvertemperature) => vocab::PlanarFault::HipOvertemperature,
        Some(PlanarFault::LegOvertemperature) => vocab::PlanarFault::LegOvertemperature,
    };
    f.code()
}

impl PlanarPort {
    /// Disarmed, telemetry off, for a machine whose period is `period_s`;
    /// `simulated` takes the simulated e-stop and hoist. `cfg` is checked.
    pub fn new(cfg: ArmingConfig, period_s: f32, simulated: bool) -> Result<Self, InvalidField> {
        Ok(Self {
            rx: Decoder::new(),
            arming: Arming::new(cfg)?,
            period_s,
            simulated,
            estop_pressed: false,
            estop_latched: false,
            pending: None,
            memo: Memos::new(),
            mount: None,
            every: 0,
            since: 0,
            seq: 0,
            dropped: 0,
            periods: 0,
            last: PlanarTelemetry {
                seq: 0,
                step: 0,
                armed: false,
                stance: false,
                fault: 0,
                x_m: f32::NAN,
                z_m: f32::NAN,
                pitch_rad: f32::NAN,
                leg_angle_rad: f32::NAN,
                leg_length_m: f32::NAN,
                speed_mps: f32::NAN,
                speed_command_mps: 0.0,
                hip_current_a: 0.0,
                leg_current_a: 0.0,
            },
            last_apex_m: f32::NAN,
            thermal: ThermalStatus {
                winding_c: f32::NAN,
                housing_c: f32::NAN,
                limit_scale: 1.0,
                derate_c: f32::NAN,
                trip_c: f32::NAN,
                protect: true,
            },
            fault_latched: None,
        })
    }

    /// Whether both amplifiers may be on.
    pub fn armed(&self) -> bool {
        self.arming.is_armed()
    }

    /// The e-stop input (a board's, debounced); the simulated robot's is
    /// set by [`Request::SimulateEstop`]. A press disarms at the next
    /// period and stays latched until released and reset.
    pub fn set_estop(&mut self, pressed: bool) {
        self.estop_pressed = pressed;
        // A press released before the next period still counts.
        self.estop_latched |= pressed;
    }

    /// What the host asked of the simulated body since the last call.
    pub fn take_mount(&mut self) -> Option<Mount> {
        self.mount.take()
    }

    /// The bytes that came from the host: each message decoded and
    /// answered, or kept for the next period to decide.
    pub fn receive<T: Tx>(&mut self, bytes: impl IntoIterator<Item = u8>, tx: &mut T) {
        for b in bytes {
            let Some(msg) = self.rx.push::<HostMsg>(b) else {
                continue;
            };
            self.arming.link_frame();
            match msg {
                HostMsg::Hello { .. } => {
                    // A new session numbers its requests from the start
                    // again: the last session's answers are not its own.
                    self.memo.clear();
                    send_hello(tx);
                }
                HostMsg::Request { id, req } if req.acts() => {
                    let known = self.memo.iter().find(|(i, _)| *i == id).map(|m| m.1);
                    let resp = match known {
                        // A retry of what waits for its period: its answer
                        // comes then.
                        Some(Memo::InFlight) => None,
                        Some(Memo::Ok) => Some(Response::Ok),
                        Some(Memo::Refused(why)) => Some(Response::Refused(why)),
                        None => {
                            let resp = self.act(id, &req, tx);
                            let memo = resp.as_ref().map_or(Some(Memo::InFlight), Memo::of);
                            if let Some(m) = memo {
                                remember(&mut self.memo, id, m);
                            }
                            resp
                        }
                    };
                    if let Some(resp) = resp {
                        send(tx, &RobotMsg::Response { id, resp }, false);
                    }
                }
                HostMsg::Request { id, req } => {
                    let resp = self.query(&req);
                    send(tx, &RobotMsg::Response { id, resp }, false);
                }
                HostMsg::Heartbeat | HostMsg::HilSample(_) => {}
            }
        }
    }

    /// Answers the request `id` with `resp`, remembered for its retries.
    fn answer<T: Tx>(&mut self, id: u16, resp: Response, tx: &mut T) {
        if let Some(m) = Memo::of(&resp) {
            remember(&mut self.memo, id, m);
        }
        send(tx, &RobotMsg::Response { id, resp }, false);
    }

    /// A request that acts: its answer, or `None` when the next period
    /// decides it.
    fn act<T: Tx>(&mut self, id: u16, req: &Request, tx: &mut T) -> Option<Response> {
        let decided = match req {
            Request::Arm => Pending::Arm,
            Request::Disarm => Pending::Disarm,
            Request::ResetFaults if self.armed() => return Some(refused(Refusal::DisarmFirst)),
            Request::ResetFaults => Pending::Reset,
            Request::SimulateEstop { pressed } if self.simulated => {
                self.set_estop(*pressed);
                return Some(Response::Ok);
            }
            Request::SimulateMount { .. } | Request::SimulateEstop { .. } if !self.simulated => {
                return Some(refused(Refusal::NotSimulated));
            }
            Request::SimulateMount { .. } if self.armed() => {
                return Some(refused(Refusal::DisarmFirst))
            }
            Request::SimulateMount { hoisted, lift_m } => {
                return Some(if !*hoisted {
                    self.mount = Some(Mount::Release);
                    Response::Ok
                } else if crate::LIFT_RANGE_M.contains(lift_m) {
                    self.mount = Some(Mount::Hoist { toe_m: *lift_m });
                    Response::Ok
                } else {
                    refused(Refusal::LiftOutOfRange)
                });
            }
            Request::ParamSet { .. } => return Some(refused(Refusal::UnknownParameter)),
            _ => return Some(refused(Refusal::NotThisMachine)),
        };
        match self.pending {
            // The retry of what waits (its memory forgotten): its answer
            // comes with its period.
            Some((old, _)) if old == id => None,
            // A disarm is never refused as busy: what waited is answered
            // now (a disarm like it, done; anything else, superseded) and
            // the disarm decided instead.
            Some((old, was)) if decided == Pending::Disarm => {
                let resp = if was == Pending::Disarm {
                    Response::Ok
                } else {
                    refused(Refusal::DisarmRequested)
                };
                self.answer(old, resp, tx);
                self.pending = Some((id, decided));
                None
            }
            Some(_) => Some(refused(Refusal::Busy)),
            None => {
                self.pending = Some((id, decided));
                None
            }
        }
    }

    /// The answer to a request that only reads.
    fn query(&mut self, req: &Request) -> Response {
        match req {
            Request::Status => Response::Status(Status {
                arm: crate::arm_state(self.arming.state()),
                faults: self.status_faults(),
                periods: self.periods,
                frames_ok: self.rx.stats().ok,
                frames_bad: self.rx.stats().bad(),
                telemetry_dropped: self.dropped,
                last_apex_m: self.last_apex_m,
            }),
            Request::Telemetry { every } => {
                self.every = *every;
                self.since = 0;
                Response::Ok
            }
            Request::Timing => Response::Timing(TimingStats {
                period_s: self.period_s,
                periods: self.periods,
                missed: 0,
                step_mean: 0,
                step_max: 0,
                link_mean: 0,
                link_max: 0,
            }),
            Request::Thermal => Response::Thermal(self.thermal),
            Request::ParamCount => Response::ParamCount(0),
            Request::ParamInfo { .. } => refused(Refusal::NoSuchIndex),
            Request::ParamGet { .. } | Request::ParamMeta { .. } | Request::ParamChoice { .. } => {
                refused(Refusal::UnknownParameter)
            }
            _ => refused(Refusal::NotThisMachine),
        }
    }

    /// The latched faults as [`Status::faults`] has them.
    fn status_faults(&self) -> u16 {
        status_faults(self.fault_latched) | self.estop_bit()
    }

    /// The e-stop's latch as a fault bit.
    fn estop_bit(&self) -> u16 {
        if self.estop_latched {
            Fault::Estop.bit()
        } else {
            0
        }
    }

    /// What the arming decides on: this period's estimate, the guard's
    /// latch, the e-stop, the nut.
    fn arm_input<L: LegDrive>(&self, period: &PlanarPeriod<L>, est: &PlanarEstimate) -> ArmInput {
        let posture = match period.fault() {
            Some(_) => POSTURE_BIT,
            None => 0,
        };
        ArmInput {
            faults: Faults(status_faults(period.fault()) | posture | self.estop_bit()),
            estop_pressed: self.estop_pressed,
            sensors_ok: est.is_finite(),
            nut_position_m: period.nut_position_m(),
            nut_velocity_mps: period.nut_velocity_mps(),
            // Still means still both ways.
            body_velocity_mps: libm::fabsf(est.x_dot_mps).max(libm::fabsf(est.z_dot_mps)),
            calibrating: false,
        }
    }

    /// One period of the machine: its readings `readings` through the
    /// estimator; what waited decided on that estimate (an arm, a
    /// disarm, a reset); the controller at the commanded speed with both
    /// amplifiers enabled only if armed, and disarmed in the same period
    /// if its guard latches; then the state's changes, the answers and
    /// the telemetry sent.
    pub fn period<L: LegDrive, T: Tx>(
        &mut self,
        period: &mut PlanarPeriod<L>,
        readings: &PlanarReadings,
        speed_command_mps: f32,
        dt_s: f32,
        tx: &mut T,
    ) -> Output {
        let est = period.estimate_from(readings, dt_s);
        let est = &est;
        let pending = self.pending.take();
        let mut reset_ok = false;
        match pending {
            Some((_, Pending::Arm)) => self.arming.request_arm(),
            Some((_, Pending::Disarm)) => self.arming.request_disarm(),
            // All or nothing: the e-stop released, then the guard's
            // latch with its cause gone.
            Some((_, Pending::Reset)) if !self.estop_pressed => {
                reset_ok = period.reset_fault(est).is_ok();
                if reset_ok {
                    self.estop_latched = false;
                }
            }
            Some((_, Pending::Reset)) | None => {}
        }
        self.estop_latched |= self.estop_pressed;
        let input = self.arm_input(period, est);
        let event = self.arming.period(dt_s, &input);
        let out = period.control_armed(est, speed_command_mps, dt_s, self.arming.is_armed());
        // A limit the guard latched in this period's control disarms now:
        // its command is zero already, and the enables go off with it.
        let latched = match period.fault() {
            Some(_) => self.arming.fault_latched(),
            None => None,
        };
        let armed = self.arming.is_armed();
        self.fault_latched = period.fault();
        if let Some((id, p)) = pending {
            let resp = match p {
                Pending::Arm if armed => Response::Ok,
                Pending::Arm => {
                    let why = match event {
                        Some(ArmEvent::Refused(r)) => Some(r),
                        // Armed and disarmed again in this period, or a
                        // disarm in the same interval: why it is not armed
                        // now.
                        _ => self.arming.refusal(&self.arm_input(period, est)),
                    };
                    refused(why.map_or(Refusal::DisarmRequested, crate::arm_refusal))
                }
                // A reset whose cause came back within the period did not
                // take.
                Pending::Reset if reset_ok && period.fault().is_none() => Response::Ok,
                Pending::Reset => refused(Refusal::FaultsRemain),
                Pending::Disarm => Response::Ok,
            };
            self.answer(id, resp, tx);
        }
        for e in [event, latched] {
            let state = match e {
                // (Armed and disarmed again in this period: only the
                // disarm is news.)
                Some(ArmEvent::Armed) if !armed => continue,
                Some(ArmEvent::Armed) => ArmState::Armed,
                Some(ArmEvent::Disarmed(r)) => ArmState::Disarmed(r),
                _ => continue,
            };
            send(tx, &RobotMsg::State(crate::arm_state(state)), false);
        }
        self.note(period, est, readings, &out, armed, speed_command_mps);
        if self.every > 0 {
            self.since += 1;
            if self.since >= self.every {
                self.since = 0;
                let rec = PlanarTelemetry {
                    seq: self.seq,
                    ..self.last
                };
                self.seq = self.seq.wrapping_add(1);
                if !send(tx, &RobotMsg::Planar(rec), true) {
                    self.dropped = self.dropped.wrapping_add(1);
                }
            }
        }
        self.periods = self.periods.wrapping_add(1);
        Output {
            cmd: out,
            enabled: armed,
            armed_now: armed && matches!(event, Some(ArmEvent::Armed)),
        }
    }

    /// This period into the state the answers read.
    fn note<L: LegDrive>(
        &mut self,
        period: &PlanarPeriod<L>,
        est: &PlanarEstimate,
        r: &PlanarReadings,
        out: &PlanarCommand,
        armed: bool,
        speed_command_mps: f32,
    ) {
        if let Some(apex_m) = period.last_apex_m() {
            self.last_apex_m = apex_m;
        }
        let hot = period.hotter_winding();
        self.thermal = ThermalStatus {
            winding_c: hot.winding_c(),
            housing_c: hot.housing_c(),
            limit_scale: hot.limit_scale(),
            derate_c: hot.config().derate_winding_c,
            trip_c: hot.config().trip_winding_c,
            protect: hot.config().protect,
        };
        self.last = PlanarTelemetry {
            seq: self.seq,
            step: self.periods,
            armed,
            stance: est.stance,
            fault: planar_fault(period.fault()),
            x_m: r.boom_x_m,
            z_m: est.z_m,
            pitch_rad: est.phi_rad,
            leg_angle_rad: est.theta_rad,
            leg_length_m: r.leg_length_m,
            speed_mps: est.x_dot_mps,
            speed_command_mps,
            hip_current_a: period.hip_current_a(),
            leg_current_a: out.leg_current_a,
        };
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::tests::VecTx;
    use hopper_control::planar::raibert::RaibertConfig;
    use hopper_control::planar::{HipDrive, TABLE_2_2_LEG_LENGTH_M};
    use hopper_protocol::{encode, MAX_FRAME, PROTOCOL_VERSION};
    use proptest::prelude::*;
    use std::vec::Vec;

    const DT_S: f32 = 1e-4;

    /// The planar machine's firmware behind a byte link.
    struct Robot {
        period: PlanarPeriod,
        port: PlanarPort,
        readings: PlanarReadings,
        tx: VecTx,
        host: Decoder,
        inbox: Vec<u8>,
    }

    /// Standing upright on its toe on the boom, the leg at rest.
    fn standing() -> PlanarReadings {
        PlanarReadings {
            boom_x_m: 0.0,
            boom_z_m: 0.64,
            pitch_rad: 0.0,
            hip_angle_rad: 0.0,
            leg_length_m: 0.64,
            leg_motor_rad: 0.0,
        }
    }

    impl Robot {
        fn new(simulated: bool) -> Self {
            let period = PlanarPeriod::new(
                RaibertConfig::table_2_2(),
                TABLE_2_2_LEG_LENGTH_M,
                HipDrive::design(),
                false,
            )
            .unwrap_or_else(|e| panic!("{e:?}"));
            let port = PlanarPort::new(ArmingConfig::default(), DT_S, simulated)
                .unwrap_or_else(|e| panic!("{e:?}"));
            Robot {
                period,
                port,
                readings: standing(),
                tx: VecTx {
                    bytes: Vec::new(),
                    cap: 4096,
                },
                host: Decoder::new(),
                inbox: Vec::new(),
            }
        }

        fn request(&mut self, id: u16, req: Request) {
            let mut f = [0u8; MAX_FRAME];
            let n =
                encode(&HostMsg::Request { id, req }, &mut f).unwrap_or_else(|e| panic!("{e:?}"));
            self.inbox.extend_from_slice(&f[..n]);
        }

        /// One period: the bytes that came, then the machine's period and
        /// the port's.
        fn period(&mut self) -> Output {
            let bytes = core::mem::take(&mut self.inbox);
            self.port.receive(bytes, &mut self.tx);
            self.port
                .period(&mut self.period, &self.readings, 0.5, DT_S, &mut self.tx)
        }

        fn periods(&mut self, n: usize) -> Output {
            let mut last = self.period();
            for _ in 1..n {
                last = self.period();
            }
            last
        }

        /// What the robot sent since the last call.
        fn sent(&mut self) -> Vec<RobotMsg> {
            let bytes = core::mem::take(&mut self.tx.bytes);
            bytes
                .iter()
                .filter_map(|&b| self.host.push::<RobotMsg>(b))
                .collect()
        }

        fn answer(&mut self, id: u16) -> Response {
            self.sent()
                .into_iter()
                .find_map(|m| match m {
                    RobotMsg::Response { id: i, resp } if i == id => Some(resp),
                    _ => None,
                })
                .unwrap_or_else(|| panic!("no answer to {id}"))
        }
    }

    fn no(r: Refusal) -> Response {
        refused(r)
    }

    /// Disarmed at boot: 0 A on both amplifiers, their enables off,
    /// whatever the controller asks. Armed on request; then a link that
    /// goes quiet for the arming's 0.2 s disarms it, in the period it
    /// expires, and both currents are 0 again.
    #[test]
    fn both_amplifiers_off_until_armed_and_after_the_link_goes_quiet() {
        let mut r = Robot::new(false);
        // Leaning, so that the controller asks for a hip torque.
        r.readings.pitch_rad = 0.1;
        let out = r.periods(100);
        assert!(!out.enabled);
        assert_eq!(out.cmd, PlanarCommand::default());
        r.request(1, Request::Arm);
        let out = r.period();
        assert_eq!(r.answer(1), Response::Ok);
        assert!(out.enabled && out.armed_now);
        assert!(out.cmd.hip_torque_nm.abs() > 1.0, "{:?}", out.cmd);
        // 0.2 s = 2000 periods without a frame (to within the sum's
        // rounding).
        let out = r.periods(1990);
        assert!(out.enabled);
        let out = r.periods(20);
        assert!(!out.enabled);
        assert_eq!(out.cmd, PlanarCommand::default());
        assert!(r
            .sent()
            .contains(&RobotMsg::State(hopper_protocol::ArmState::Disarmed(5))));
        // A dead link does not arm: the arm request is a frame, so the
        // link lives again, and it arms.
        r.request(2, Request::Arm);
        r.period();
        assert_eq!(r.answer(2), Response::Ok);
    }

    /// The guard's latch (the body pitched past its 0.52 rad) disarms
    /// both amplifiers in the period it latches and is named on the wire;
    /// it resets only while disarmed and once the body is back within
    /// its limits, and only then may the machine arm again.
    #[test]
    fn a_fall_disarms_both_amplifiers_and_resets_only_once_upright() {
        let mut r = Robot::new(false);
        r.request(1, Request::Telemetry { every: 1 });
        r.request(2, Request::Arm);
        r.period();
        assert_eq!(r.answer(2), Response::Ok);
        r.readings.pitch_rad = 0.6;
        let out = r.period();
        assert!(!out.enabled);
        assert_eq!(out.cmd, PlanarCommand::default());
        let sent = r.sent();
        assert!(sent.contains(&RobotMsg::State(hopper_protocol::ArmState::Disarmed(4))));
        let rec = sent.iter().rev().find_map(|m| match m {
            RobotMsg::Planar(t) => Some(*t),
            _ => None,
        });
        assert_eq!(
            rec.map(|t| (t.fault, t.armed)),
            Some((vocab::PlanarFault::Pitch.code(), false))
        );
        r.request(3, Request::Arm);
        r.period();
        assert_eq!(r.answer(3), no(Refusal::Faulted));
        r.request(4, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(4), no(Refusal::FaultsRemain));
        r.readings.pitch_rad = 0.0;
        r.periods(10);
        r.request(5, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(5), Response::Ok);
        r.request(6, Request::Arm);
        let out = r.period();
        assert_eq!(r.answer(6), Response::Ok);
        assert!(out.enabled);
        // Armed, a reset is refused: disarm first.
        r.request(7, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(7), no(Refusal::DisarmFirst));
    }

    /// The e-stop disarms and refuses arming while pressed; released, its
    /// press stays latched (arming refused `faulted`) until the faults are
    /// reset, as on the vertical hopper. A disarm while an arm waits
    /// answers the arm and is never refused as busy; a second disarm is
    /// answered done.
    #[test]
    fn the_estop_latches_and_a_disarm_wins() {
        let mut r = Robot::new(true);
        r.request(1, Request::Arm);
        r.period();
        assert_eq!(r.answer(1), Response::Ok);
        r.request(2, Request::SimulateEstop { pressed: true });
        let out = r.period();
        assert_eq!(r.answer(2), Response::Ok);
        assert!(!out.enabled);
        r.request(3, Request::Arm);
        r.period();
        assert_eq!(r.answer(3), no(Refusal::EstopPressed));
        r.request(4, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(4), no(Refusal::FaultsRemain));
        r.request(5, Request::SimulateEstop { pressed: false });
        r.request(6, Request::Arm);
        r.period();
        assert_eq!(r.answer(6), no(Refusal::Faulted));
        r.request(7, Request::Status);
        r.period();
        match r.answer(7) {
            Response::Status(s) => assert_eq!(s.faults, Fault::Estop.bit()),
            a => panic!("{a:?}"),
        }
        r.request(8, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(8), Response::Ok);
        r.request(9, Request::Arm);
        r.request(10, Request::Disarm);
        r.request(11, Request::Disarm);
        let out = r.period();
        let sent = r.sent();
        let answer = |id| {
            sent.iter().find_map(|m| match m {
                RobotMsg::Response { id: i, resp } if *i == id => Some(resp.clone()),
                _ => None,
            })
        };
        assert_eq!(answer(9), Some(no(Refusal::DisarmRequested)));
        assert_eq!(answer(10), Some(Response::Ok));
        assert_eq!(answer(11), Some(Response::Ok));
        assert!(!out.enabled);
    }

    /// A host's retry of a request that acts (its answer lost, or late)
    /// is answered from the robot's memory of its id, never carried out
    /// again: an arm refused stays refused when the cause is gone, and an
    /// arm done is not done again after a disarm.
    #[test]
    fn a_retried_arm_is_answered_again_never_carried_out_twice() {
        let mut r = Robot::new(true);
        r.request(1, Request::SimulateEstop { pressed: true });
        r.request(2, Request::Arm);
        r.period();
        assert_eq!(r.answer(2), no(Refusal::EstopPressed));
        r.request(3, Request::SimulateEstop { pressed: false });
        r.request(4, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(4), Response::Ok);
        // The retry of the refused arm: the same refusal, still disarmed.
        r.request(2, Request::Arm);
        let out = r.period();
        assert_eq!(r.answer(2), no(Refusal::EstopPressed));
        assert!(!out.enabled);
        // Armed, disarmed, then the arm's retry: answered, not re-armed.
        r.request(5, Request::Arm);
        r.period();
        assert_eq!(r.answer(5), Response::Ok);
        r.request(6, Request::Disarm);
        r.period();
        assert_eq!(r.answer(6), Response::Ok);
        r.request(5, Request::Arm);
        let out = r.periods(3);
        assert_eq!(r.answer(5), Response::Ok);
        assert!(!out.enabled);
        // A retry while its period has not come yet gets one answer.
        r.request(7, Request::Arm);
        r.request(7, Request::Arm);
        r.period();
        let answers = r
            .sent()
            .into_iter()
            .filter(|m| matches!(m, RobotMsg::Response { id: 7, .. }))
            .count();
        assert_eq!(answers, 1);
    }

    /// A new session (its hello) numbers its requests from 1 again: its
    /// disarm is carried out, not answered from the last session's
    /// memory of the same id.
    #[test]
    fn a_new_sessions_requests_are_its_own() {
        let mut r = Robot::new(false);
        r.request(1, Request::Arm);
        r.period();
        r.request(2, Request::Disarm);
        r.period();
        assert_eq!(r.answer(2), Response::Ok);
        let mut f = [0u8; MAX_FRAME];
        let n = encode(
            &HostMsg::Hello {
                version: PROTOCOL_VERSION,
            },
            &mut f,
        )
        .unwrap_or_else(|e| panic!("{e:?}"));
        r.inbox.extend_from_slice(&f[..n]);
        r.request(1, Request::Arm);
        let out = r.period();
        assert_eq!(r.answer(1), Response::Ok);
        assert!(out.enabled);
        r.request(2, Request::Disarm);
        let out = r.period();
        assert_eq!(r.answer(2), Response::Ok);
        assert!(!out.enabled);
    }

    /// An arm decided in the period whose control latches a limit is
    /// refused (`faulted`), and the held body is not let go.
    #[test]
    fn an_arm_in_the_period_a_limit_latches_is_refused() {
        let mut r = Robot::new(false);
        r.periods(10);
        r.request(1, Request::Arm);
        r.readings.pitch_rad = 0.6;
        let out = r.period();
        let sent = r.sent();
        assert!(sent.contains(&RobotMsg::Response {
            id: 1,
            resp: no(Refusal::Faulted)
        }));
        assert!(!out.enabled && !out.armed_now);
        assert_eq!(out.cmd, PlanarCommand::default());
        // No state says armed: only the disarm is sent.
        let states: Vec<&RobotMsg> = sent
            .iter()
            .filter(|m| matches!(m, RobotMsg::State(_)))
            .collect();
        assert_eq!(
            states,
            [&RobotMsg::State(hopper_protocol::ArmState::Disarmed(4))]
        );
    }

    /// A winding's trip resets only once it has cooled below its
    /// derating temperature (135 C), not as soon as it is below its trip
    /// (150 C): the hip held at its current limit against a lean until
    /// its winding trips, then left to cool, disarmed.
    #[test]
    fn an_overtemperature_resets_only_once_cooled() {
        let mut r = Robot::new(false);
        r.request(1, Request::Arm);
        r.period();
        assert_eq!(r.answer(1), Response::Ok);
        // Leaning, standing: the hip pushes its limit.
        r.readings.pitch_rad = 0.4;
        let mut heated = 0;
        while r.period.fault().is_none() && heated < 20_000_000 {
            // The link kept alive.
            if heated % 1000 == 0 {
                r.inbox.extend_from_slice(&[0]);
                r.request(2, Request::Status);
            }
            r.period();
            heated += 1;
        }
        assert_eq!(r.period.fault(), Some(PlanarFault::HipOvertemperature));
        let trip_c = r.period.hotter_winding().config().trip_winding_c;
        let derate_c = r.period.hotter_winding().config().derate_winding_c;
        r.readings.pitch_rad = 0.0;
        // Below its trip, above its derating: refused.
        while r.period.hip_winding_c() >= trip_c - 1.0 {
            r.period();
        }
        r.sent();
        r.request(3, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(3), no(Refusal::FaultsRemain));
        while r.period.hip_winding_c() >= derate_c {
            r.period();
        }
        r.request(4, Request::ResetFaults);
        r.period();
        assert_eq!(r.answer(4), Response::Ok);
    }

    /// What the planar robot has not is refused by name; the hoist is the
    /// simulator's, within its range and only while disarmed.
    #[test]
    fn what_the_planar_robot_has_not_is_refused_by_name() {
        let mut r = Robot::new(false);
        let cases = [
            (Request::Dump, no(Refusal::NotThisMachine)),
            (Request::Cost, no(Refusal::NotThisMachine)),
            (Request::ParamCount, Response::ParamCount(0)),
            (Request::ParamInfo { index: 0 }, no(Refusal::NoSuchIndex)),
            (
                Request::SimulateMount {
                    hoisted: true,
                    lift_m: 0.1,
                },
                no(Refusal::NotSimulated),
            ),
        ];
        for (id, (req, want)) in (1..).zip(cases) {
            r.request(id, req);
            r.period();
            assert_eq!(r.answer(id), want);
        }
        let mut r = Robot::new(true);
        r.request(
            1,
            Request::SimulateMount {
                hoisted: true,
                lift_m: 0.9,
            },
        );
        r.period();
        assert_eq!(r.answer(1), no(Refusal::LiftOutOfRange));
        r.request(
            2,
            Request::SimulateMount {
                hoisted: true,
                lift_m: 0.1,
            },
        );
        r.period();
        assert_eq!(r.answer(2), Response::Ok);
        assert_eq!(r.port.take_mount(), Some(Mount::Hoist { toe_m: 0.1 }));
        r.request(3, Request::Arm);
        r.period();
        r.request(
            4,
            Request::SimulateMount {
                hoisted: false,
                lift_m: 0.0,
            },
        );
        r.period();
        assert_eq!(r.answer(4), no(Refusal::DisarmFirst));
        assert_eq!(r.port.take_mount(), None);
    }

    /// Telemetry comes every `every` periods, numbered without a gap; a
    /// record the line has no room for is counted, and the state still
    /// gets through.
    #[test]
    fn telemetry_at_its_rate_and_its_drops_counted() {
        let mut r = Robot::new(false);
        r.request(1, Request::Telemetry { every: 10 });
        r.periods(100);
        let seqs: Vec<u32> = r
            .sent()
            .into_iter()
            .filter_map(|m| match m {
                RobotMsg::Planar(t) => Some(t.seq),
                _ => None,
            })
            .collect();
        assert_eq!(seqs, (0..10).collect::<Vec<_>>());
        r.tx.cap = 0;
        r.periods(50);
        r.tx.cap = 4096;
        r.request(2, Request::Status);
        r.period();
        match r.answer(2) {
            Response::Status(s) => {
                assert_eq!(s.telemetry_dropped, 5);
                assert_eq!(s.periods, 150);
            }
            a => panic!("{a:?}"),
        }
    }

    proptest! {
        /// Whatever bytes come and whatever the sensors read (NaN, beyond
        /// every limit), the amplifiers are off and told 0 unless armed,
        /// and armed only with a link frame within its timeout.
        #[test]
        fn never_driven_unless_armed(
            chunks in proptest::collection::vec(
                (proptest::collection::vec(any::<u8>(), 0..40), any::<bool>(), -1.0f32..1.0, 0u8..4),
                1..60),
        ) {
            let mut r = Robot::new(true);
            let mut quiet = 0usize;
            for (bytes, arm, pitch, weird) in chunks {
                if arm {
                    r.request(9, Request::Arm);
                }
                r.inbox.extend_from_slice(&bytes);
                quiet = if r.inbox.is_empty() { quiet + 40 } else { 0 };
                r.readings.pitch_rad = match weird {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    _ => pitch,
                };
                let out = r.periods(40);
                if !out.enabled {
                    prop_assert_eq!(out.cmd, PlanarCommand::default());
                } else {
                    prop_assert!(quiet <= 2000);
                    prop_assert!(out.cmd.hip_torque_nm.is_finite());
                }
                r.sent();
            }
        }
    }
}
