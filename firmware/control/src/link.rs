//! The robot's end of the host link (issue 17): what each
//! [`hopper_protocol`] message does to the [`PeriodRunner`], and what the
//! robot sends back. The transports (a UART interrupt, QEMU's USART on a
//! TCP socket, the simulator's TCP socket) only move bytes: each period
//! the application hands [`Endpoint::service`] the bytes received since
//! the last one and a transmit queue ([`Tx`]); the endpoint decodes them,
//! answers, and queues the period's messages. One implementation, so the
//! board, the QEMU image and the simulator's virtual robot answer alike.
//!
//! - Every valid message keeps the link alive ([`crate::arming::Arming::link_frame`]).
//! - An arm request is decided at the next period; its response waits for
//!   that period (`Ok`, or `Refused` with the reason).
//! - Parameter sets go through [`PeriodRunner::set_param`].
//! - Nothing waits: a frame that finds the queue without room is not sent.
//!   Telemetry and dump records leave room for one more frame, so answers
//!   and state changes still fit when the stream fills the line; a dropped
//!   telemetry record is counted (its sequence number is used anyway, so
//!   the host sees the gap).

use crate::arming::{ArmEvent, ArmState as RunnerArmState, DisarmReason};
use crate::params;
use crate::runner::{CycleCounter, LogItem, Period, PeriodRunner, StepStats};
use crate::telemetry::{FaultCapture, StepRecord};
use hopper_protocol::{
    encode, ArmState, BootInfo, Decoder, DumpInfo, Hop, HostMsg, ParamInfo, Request, Response,
    RobotMsg, Status, StoredInfo, Telemetry, ThermalStatus, TimingStats, MAX_FRAME,
    PROTOCOL_VERSION, TEXT_LEN,
};

/// A transmit queue of bytes (the board's UART ring, a socket buffer).
pub trait Tx {
    /// Bytes it can take now.
    fn room(&self) -> usize;
    /// Appends `frame`; only called with `frame.len() <= room()`.
    fn put(&mut self, frame: &[u8]);
}

/// Dump records queued per period at most (bounds the link's work in one
/// period; the line is the real limit).
const DUMP_PER_PERIOD: u16 = 4;

/// The disarm reasons by their wire code ([`ArmState::Disarmed`]).
pub const DISARM_REASONS: [DisarmReason; 6] = [
    DisarmReason::Boot,
    DisarmReason::WatchdogReset,
    DisarmReason::Command,
    DisarmReason::Estop,
    DisarmReason::Fault,
    DisarmReason::LinkLost,
];

/// The robot's link state.
#[derive(Debug, Clone, Default)]
pub struct Endpoint {
    rx: Decoder,
    /// The id of an arm request waiting for the next period.
    pending_arm: Option<u16>,
    /// Telemetry every this many periods (0: off).
    every: u16,
    since: u16,
    seq: u32,
    telemetry_dropped: u32,
    last_apex_m: Option<f32>,
    /// A dump in progress: the next record and the count.
    dump: Option<(u16, u16)>,
    /// Where the dump's oldest record was when it started
    /// ([`FaultCapture::start`](crate::telemetry::FaultCapture::start)): a
    /// fault that latches during the dump is captured, and the records the
    /// dump reads stay the ones it announced, since it reads four a period
    /// and the capture writes one.
    dump_start: usize,
    /// The link's work per period, in the counter's ticks.
    cost: StepStats,
    /// A simulated robot ([`simulated`](Self::simulated)).
    simulated: bool,
    /// The simulated e-stop, as last asked.
    sim_estop: bool,
    /// A simulated mount change not yet taken by the application:
    /// (hoisted, lift to this toe height, m).
    sim_mount: Option<(bool, f32)>,
    /// The calibration record of the last save request, its length, and
    /// whether the application has taken it.
    save_record: SaveRecord,
    save_len: usize,
    save_taken: bool,
    /// The last save's state (`StoredInfo::save`).
    save_state: u8,
}

/// A calibration record's bytes (an array too long for a derived `Default`).
#[derive(Debug, Clone)]
struct SaveRecord([u8; crate::persist::MAX_RECORD]);

impl Default for SaveRecord {
    fn default() -> Self {
        Self([0; crate::persist::MAX_RECORD])
    }
}

const SAVE_PENDING: u8 = 1;
const SAVE_SAVED: u8 = 2;
const SAVE_FAILED: u8 = 3;
const SAVE_AT_RESTART: u8 = 4;

fn text(s: &str) -> heapless::String<TEXT_LEN> {
    let mut t = heapless::String::new();
    // Every reason is far shorter than the capacity.
    let _ = t.push_str(s);
    t
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

/// Whether setting `name` to `value` would switch a protection off
/// ([`params::PROTECTIONS`]); a NaN is not the safe value either.
fn unsafe_value(name: &str, value: f32) -> bool {
    params::PROTECTIONS
        .iter()
        .any(|(p, safe)| p.name == name && value != *safe)
}

/// Frames `msg` into `tx` if it has room for it (plus one more frame when
/// `bulk`); whether it went.
fn send<T: Tx>(tx: &mut T, msg: &RobotMsg, bulk: bool) -> bool {
    let mut f = [0u8; MAX_FRAME];
    let Ok(n) = encode(msg, &mut f) else {
        return false;
    };
    let need = if bulk { n + MAX_FRAME } else { n };
    match f.get(..n) {
        Some(frame) if tx.room() >= need => {
            tx.put(frame);
            true
        }
        _ => false,
    }
}

impl Endpoint {
    /// No session yet, telemetry off.
    pub fn new() -> Self {
        Self::default()
    }

    /// The endpoint of a simulated robot (the QEMU image, the simulator's
    /// virtual robot): it takes [`Request::SimulateEstop`], which a real
    /// robot refuses.
    pub fn simulated() -> Self {
        Self {
            simulated: true,
            ..Self::default()
        }
    }

    /// The simulated e-stop as the host last set it (always released on a
    /// real robot); the application applies it to its sensor models.
    pub fn sim_estop(&self) -> bool {
        self.sim_estop
    }

    /// The simulated mount change the host asked for since the last call
    /// (hoisted, toe height to lift to, m); the application moves its
    /// plant (never on a real robot).
    pub fn take_sim_mount(&mut self) -> Option<(bool, f32)> {
        self.sim_mount.take()
    }

    /// The calibration record a host asked to save, once (the
    /// application writes it to its flash, then calls
    /// [`save_done`](Self::save_done)); `None` when there is none.
    pub fn take_save(&mut self) -> Option<&[u8]> {
        if self.save_state != SAVE_PENDING || self.save_taken {
            return None;
        }
        self.save_taken = true;
        self.save_record.0.get(..self.save_len)
    }

    /// How the save went: written, failed, or to be written at the next
    /// boot (`deferred`: the board writes its flash in `init`).
    pub fn save_done(&mut self, ok: bool, deferred: bool) {
        self.save_state = match (ok, deferred) {
            (true, false) => SAVE_SAVED,
            (true, true) => SAVE_AT_RESTART,
            (false, _) => SAVE_FAILED,
        };
    }

    /// Telemetry records the transmit queue could not take so far.
    pub fn telemetry_dropped(&self) -> u32 {
        self.telemetry_dropped
    }

    /// The link's work per period so far ([`service`](Self::service)).
    pub fn cost(&self) -> &StepStats {
        &self.cost
    }

    /// The period's link work, right after [`PeriodRunner::run_period`]:
    /// the period's messages (the deferred arm answer, a state change,
    /// faults or a hop, a telemetry record when due, dump records), then
    /// every byte received since the last call (`rx`), decoded and
    /// answered. `capture` is the one the application records into (a
    /// dump reads it; a fault reset rearms it). Its cost, measured with
    /// `counter`, goes into [`cost`](Self::cost).
    pub fn service<const N: usize, T: Tx, C: CycleCounter>(
        &mut self,
        runner: &mut PeriodRunner,
        p: &Period,
        rx: impl Iterator<Item = u8>,
        capture: &mut FaultCapture<N>,
        tx: &mut T,
        counter: &mut C,
    ) {
        let t0 = counter.now();
        self.after_period(p, capture, tx);
        for b in rx {
            if let Some(msg) = self.rx.push::<HostMsg>(b) {
                self.on_message(&msg, runner, capture, tx);
            }
        }
        let t1 = counter.now();
        self.cost
            .add(t1.wrapping_sub(t0).saturating_sub(counter.overhead()));
    }

    /// A decoded message, between periods: queues its answer (an arm
    /// request's comes after the next period).
    pub fn on_message<const N: usize, T: Tx>(
        &mut self,
        msg: &HostMsg,
        runner: &mut PeriodRunner,
        capture: &mut FaultCapture<N>,
        tx: &mut T,
    ) {
        runner.arming_mut().link_frame();
        let (id, req) = match msg {
            HostMsg::Hello { .. } => {
                send(
                    tx,
                    &RobotMsg::Hello {
                        version: PROTOCOL_VERSION,
                    },
                    false,
                );
                return;
            }
            HostMsg::Heartbeat => return,
            HostMsg::Request { id, req } => (*id, req),
        };
        let resp = match req {
            Request::Status => Response::Status(self.status(runner)),
            // The board resets shortly to write a save: nothing starts.
            Request::Arm | Request::Calibrate { .. } if self.save_state == SAVE_AT_RESTART => {
                Response::Refused(text("restarting"))
            }
            // A save queued but not yet taken becomes a reset on the
            // board: nothing starts before it is done.
            Request::Arm | Request::Calibrate { .. } if self.save_state == SAVE_PENDING => {
                Response::Refused(text("saving"))
            }
            Request::Arm => {
                runner.arming_mut().request_arm();
                self.pending_arm = Some(id);
                return;
            }
            Request::Disarm => {
                runner.arming_mut().request_disarm();
                Response::Ok
            }
            Request::ResetFaults => {
                let input = runner.hopper().last_input().copied();
                match input.map(|i| runner.reset_faults(&i)) {
                    Some(Ok(())) => {
                        capture.rearm();
                        Response::Ok
                    }
                    _ if runner.arming().is_armed() => Response::Refused(text("disarm-first")),
                    None => Response::Refused(text("no-measurement-yet")),
                    Some(Err(_)) => Response::Refused(text("faults-remain")),
                }
            }
            Request::ParamCount => Response::ParamCount(params::TABLE.len() as u16),
            Request::ParamInfo { index } => match params::TABLE.get(usize::from(*index)) {
                Some(p) => {
                    let mut name = hopper_protocol::Name::new();
                    let _ = name.push_str(p.name);
                    let mut unit = heapless::String::new();
                    let _ = unit.push_str(p.unit);
                    Response::ParamInfo(ParamInfo {
                        name,
                        unit,
                        min: p.min,
                        max: p.max,
                        default: p.default,
                        value: params::get(runner.hopper().config(), p.name).unwrap_or(f32::NAN),
                        live: PeriodRunner::settable_while_armed(p),
                    })
                }
                None => Response::Refused(text("no-such-index")),
            },
            Request::ParamGet { name } => match params::get(runner.hopper().config(), name) {
                Ok(v) => Response::Value(v),
                Err(_) => Response::Refused(text("unknown-parameter")),
            },
            Request::ParamSet { name, value } if !self.simulated && unsafe_value(name, *value) => {
                Response::Refused(text("protection-locked"))
            }
            Request::ParamSet { name, value } => match runner.set_param(name, *value) {
                Ok(()) => Response::Ok,
                Err(e) => Response::Refused(text(e.reason())),
            },
            Request::Telemetry { every } => {
                self.every = *every;
                self.since = 0;
                Response::Ok
            }
            Request::Timing => Response::Timing(TimingStats {
                period_s: runner.timing().period_s,
                periods: runner.periods(),
                missed: runner.missed(),
                step_mean: runner.step_cost().mean(),
                step_max: runner.step_cost().max,
                link_mean: self.cost.mean(),
                link_max: self.cost.max,
            }),
            Request::Thermal => {
                let m = runner.hopper().supervisor().thermal();
                let c = m.config();
                Response::Thermal(ThermalStatus {
                    winding_c: m.winding_c(),
                    housing_c: m.housing_c(),
                    limit_scale: m.limit_scale(),
                    derate_c: c.derate_winding_c,
                    trip_c: c.trip_winding_c,
                    protect: c.protect,
                })
            }
            Request::Boot => {
                let b = runner.arming().boot();
                Response::Boot(BootInfo {
                    resets: b.resets.0,
                    brown_out_reset_on: b.brown_out_reset_on,
                    clock_as_configured: b.clock_as_configured,
                    sysclk_hz: b.sysclk_hz,
                })
            }
            Request::Calibrate { routine, seconds } => {
                match crate::bringup::Routine::from_code(*routine) {
                    None => Response::Refused(text(crate::bringup::CalRefusal::Unknown.name())),
                    Some(r) => match runner.start_calibration(r, *seconds) {
                        Ok(()) => Response::Ok,
                        Err(e) => Response::Refused(text(e.name())),
                    },
                }
            }
            Request::CalibrationReport => Response::Calibration(runner.calibration()),
            Request::BringupResults => Response::BringupResults(runner.bringup_results()),
            Request::SimulateMount { hoisted, lift_m } if self.simulated => {
                if (0.0..=0.5).contains(lift_m) {
                    self.sim_mount = Some((*hoisted, *lift_m));
                    Response::Ok
                } else {
                    Response::Refused(text("lift-out-of-range"))
                }
            }
            Request::SimulateMount { .. } => Response::Refused(text("not-simulated")),
            Request::Save if runner.arming().is_armed() => Response::Refused(text("disarm-first")),
            // An arm decided at the next period would arm a robot that the
            // save then resets.
            Request::Save if self.pending_arm.is_some() || runner.arming().arm_pending() => {
                Response::Refused(text("arming"))
            }
            Request::Save if runner.calibrating() => Response::Refused(text("calibrating")),
            // The placeholders are not a calibration: a tare (or a loaded
            // record) first, else the saved record would stand for one.
            Request::Save if !runner.arming().tared() => Response::Refused(text("not-calibrated")),
            Request::Save if self.save_state == SAVE_PENDING => Response::Refused(text("busy")),
            Request::Save => {
                self.save_len = runner.calibration_record(&mut self.save_record.0);
                self.save_taken = false;
                self.save_state = SAVE_PENDING;
                Response::Ok
            }
            Request::Weighing => Response::Weighing(runner.weighing()),
            Request::Crystal => {
                let b = runner.arming().boot();
                Response::Crystal(hopper_protocol::CrystalInfo {
                    expected_hz: b.hse_expected_hz,
                    measured_hz: b.hse_measured_hz,
                })
            }
            Request::Stored => {
                let (boot, boot_error, entries) = runner.calibration_at_boot().wire();
                Response::Stored(StoredInfo {
                    boot,
                    boot_error,
                    entries,
                    save: self.save_state,
                })
            }
            Request::SimulateEstop { pressed } if self.simulated => {
                self.sim_estop = *pressed;
                Response::Ok
            }
            Request::SimulateEstop { .. } => Response::Refused(text("not-simulated")),
            Request::Dump => {
                let records = u16::try_from(capture.len()).unwrap_or(u16::MAX);
                self.dump = Some((0, records));
                self.dump_start = capture.start();
                capture.hold(true);
                Response::Dump(DumpInfo {
                    records,
                    frozen: capture.frozen(),
                    fault_step: capture.fault_step().unwrap_or(0),
                })
            }
        };
        send(tx, &RobotMsg::Response { id, resp }, false);
    }

    /// After a period: queues the messages it produced.
    pub fn after_period<const N: usize, T: Tx>(
        &mut self,
        p: &Period,
        capture: &mut FaultCapture<N>,
        tx: &mut T,
    ) {
        // A pending arm request was decided in this period: answer it. No
        // Armed or Refused event means it changed nothing (already armed,
        // or a disarm asked for in the same batch won).
        if let Some(id) = self.pending_arm.take() {
            let resp = match p.arm_event {
                Some(ArmEvent::Refused(r)) => Response::Refused(text(r.name())),
                _ if p.armed => Response::Ok,
                _ => Response::Refused(text("disarm-requested")),
            };
            send(tx, &RobotMsg::Response { id, resp }, false);
        }
        if let Some(ev) = p.arm_event {
            let state = match ev {
                ArmEvent::Armed => Some(ArmState::Armed),
                ArmEvent::Disarmed(r) => Some(arm_state(RunnerArmState::Disarmed(r))),
                ArmEvent::Refused(_) => None,
            };
            if let Some(s) = state {
                send(tx, &RobotMsg::State(s), false);
            }
        }
        match p.log {
            Some(LogItem::Faults { step, faults }) => {
                send(
                    tx,
                    &RobotMsg::Faults {
                        step,
                        bits: faults.0,
                    },
                    false,
                );
            }
            Some(LogItem::Hop(h)) => {
                self.last_apex_m = Some(h.apex_height_m);
                let hop = Hop {
                    hop: h.hop,
                    apex_height_m: h.apex_height_m,
                    energy_at_touchdown_j: h.energy_at_touchdown_j,
                    energy_at_liftoff_j: h.energy_at_liftoff_j,
                    stance_work_j: h.stance_work_j,
                    stance_duration_s: h.stance_duration_s,
                    peak_current_a: h.peak_current_a,
                    peak_stroke_m: h.peak_stroke_m,
                };
                send(tx, &RobotMsg::Hop(hop), false);
            }
            None => {}
        }
        if self.every > 0 {
            self.since = self.since.saturating_add(1);
            if self.since >= self.every {
                self.since = 0;
                let t = RobotMsg::Telemetry(wire_record(self.seq, &p.out.record));
                // The sequence number advances for a dropped record too:
                // the host sees the gap.
                self.seq = self.seq.wrapping_add(1);
                if !send(tx, &t, true) {
                    self.telemetry_dropped = self.telemetry_dropped.saturating_add(1);
                }
            }
        }
        if let Some((mut next, total)) = self.dump {
            let end = total.min(next.saturating_add(DUMP_PER_PERIOD));
            while next < end {
                let Some(r) = capture.get_from(self.dump_start, usize::from(next)) else {
                    break;
                };
                if !send(
                    tx,
                    &RobotMsg::Captured(wire_record(u32::from(next), r)),
                    true,
                ) {
                    break;
                }
                next += 1;
            }
            self.dump = (next < total
                && capture
                    .get_from(self.dump_start, usize::from(next))
                    .is_some())
            .then_some((next, total));
            if self.dump.is_none() {
                capture.hold(false);
            }
        }
    }

    fn status(&self, runner: &PeriodRunner) -> Status {
        let link = self.rx.stats();
        Status {
            arm: arm_state(runner.arming().state()),
            faults: runner.hopper().supervisor().faults().0,
            periods: runner.periods(),
            frames_ok: link.ok,
            frames_bad: link.bad(),
            telemetry_dropped: self.telemetry_dropped,
            last_apex_m: self.last_apex_m.unwrap_or(f32::NAN),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::hal::{HopperIo, IoError, RawSample};
    use crate::hopper::HopperConfig;
    use crate::runner::{NoCounter, Timing};
    use hopper_protocol::{encode, Decoder, MAX_FRAME};
    use std::vec::Vec;

    struct Io(RawSample);
    impl HopperIo for Io {
        type Error = ();
        fn read(&mut self) -> Result<RawSample, IoError<()>> {
            Ok(self.0)
        }
        fn write_dac(&mut self, _: u16) -> Result<(), IoError<()>> {
            Ok(())
        }
        fn set_amp_enabled(&mut self, _: bool) -> Result<(), IoError<()>> {
            Ok(())
        }
    }

    /// The transmit queue: a byte vector with a fixed room.
    struct VecTx {
        bytes: Vec<u8>,
        cap: usize,
    }
    impl Tx for VecTx {
        fn room(&self) -> usize {
            self.cap.saturating_sub(self.bytes.len())
        }
        fn put(&mut self, frame: &[u8]) {
            self.bytes.extend_from_slice(frame);
        }
    }

    /// A robot at rest behind a byte link: host bytes in, robot messages
    /// out, serviced after each period as the applications do.
    struct Robot {
        runner: PeriodRunner,
        io: Io,
        ep: Endpoint,
        capture: FaultCapture<64>,
        inbox: Vec<u8>,
        tx: VecTx,
        host: Decoder,
    }

    impl Robot {
        fn new() -> Self {
            let cfg = HopperConfig::default();
            let raw = crate::proptest_support::rest_sample(&cfg.calibration);
            Robot {
                runner: PeriodRunner::new(cfg, Timing::default())
                    .unwrap_or_else(|e| panic!("{e:?}")),
                io: Io(raw),
                ep: Endpoint::new(),
                capture: FaultCapture::new(),
                inbox: Vec::new(),
                tx: VecTx {
                    bytes: Vec::new(),
                    cap: 4096,
                },
                host: Decoder::new(),
            }
        }

        /// Host bytes arrive (serviced after the next period).
        fn receive(&mut self, bytes: &[u8]) {
            self.inbox.extend_from_slice(bytes);
        }

        fn send(&mut self, msg: &HostMsg) {
            let mut f = [0u8; MAX_FRAME];
            let n = encode(msg, &mut f).unwrap_or_else(|e| panic!("{e:?}"));
            self.receive(&f[..n]);
        }

        fn request(&mut self, id: u16, req: Request) {
            self.send(&HostMsg::Request { id, req });
        }

        fn periods(&mut self, n: usize) -> Period {
            let mut last = None;
            for _ in 0..n {
                let p = self.runner.run_period(&mut self.io, &mut NoCounter);
                self.runner.end_period(false);
                self.capture
                    .record(&p.out.record, !p.newly_latched.is_empty());
                let inbox = core::mem::take(&mut self.inbox);
                self.ep.service(
                    &mut self.runner,
                    &p,
                    inbox.into_iter(),
                    &mut self.capture,
                    &mut self.tx,
                    &mut NoCounter,
                );
                last = Some(p);
            }
            last.unwrap_or_else(|| panic!("no period"))
        }

        /// What the robot sent so far, decoded as the host does.
        fn take(&mut self) -> Vec<RobotMsg> {
            let bytes = core::mem::take(&mut self.tx.bytes);
            let host = &mut self.host;
            let msgs: Vec<RobotMsg> = bytes.iter().filter_map(|&b| host.push(b)).collect();
            assert_eq!(host.stats().bad(), 0, "the robot sent a bad frame");
            msgs
        }
    }

    fn name(s: &str) -> hopper_protocol::Name {
        let mut n = hopper_protocol::Name::new();
        let _ = n.push_str(s);
        n
    }

    /// Every arm request gets an answer: a second one while armed is `Ok`,
    /// one that a disarm in the same batch overrides is refused.
    #[test]
    fn every_arm_request_is_answered() {
        let mut r = Robot::new();
        r.request(1, Request::Arm);
        r.periods(2);
        r.take();
        assert!(r.runner.arming().is_armed());
        r.request(2, Request::Arm);
        r.periods(2);
        assert!(r.take().contains(&RobotMsg::Response {
            id: 2,
            resp: Response::Ok
        }));
        r.request(3, Request::Disarm);
        r.request(4, Request::Arm);
        r.periods(2);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 4,
                resp: Response::Refused(text("disarm-requested"))
            }),
            "{msgs:?}"
        );
        assert!(!r.runner.arming().is_armed());
        // A controller rebuilt by a set and an arm in the same batch: the
        // new velocity filters have measured nothing yet, so the arm waits.
        r.request(
            5,
            Request::ParamSet {
                name: name("controller"),
                value: 8.0,
            },
        );
        r.request(6, Request::Arm);
        r.periods(2);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 6,
                resp: Response::Refused(text("sensors-implausible"))
            }),
            "{msgs:?}"
        );
    }

    /// A real robot's endpoint refuses the simulated e-stop; a simulated
    /// one takes it.
    #[test]
    fn only_a_simulated_robot_takes_the_simulated_estop() {
        for (sim, expect) in [
            (false, Response::Refused(text("not-simulated"))),
            (true, Response::Ok),
        ] {
            let mut r = Robot::new();
            if sim {
                r.ep = Endpoint::simulated();
            }
            r.request(1, Request::SimulateEstop { pressed: true });
            r.periods(1);
            assert_eq!(
                r.take(),
                [RobotMsg::Response {
                    id: 1,
                    resp: expect
                }]
            );
            assert_eq!(r.ep.sim_estop(), sim);
        }
    }

    /// A real robot's link refuses to switch a protection off (and takes
    /// its safe value); a simulated robot takes both.
    #[test]
    fn a_robot_link_refuses_to_switch_protections_off() {
        for sim in [false, true] {
            let mut r = Robot::new();
            if sim {
                r.ep = Endpoint::simulated();
            }
            for (id, name, value) in [
                (1, "thermal.protect", 0.0),
                (2, "arming.untethered", 1.0),
                (3, "thermal.protect", f32::NAN),
            ] {
                let mut n = hopper_protocol::Name::new();
                let _ = n.push_str(name);
                r.request(id, Request::ParamSet { name: n, value });
                r.periods(1);
                let expect = match (sim, value.is_nan()) {
                    (false, _) => Response::Refused(text("protection-locked")),
                    (true, false) => Response::Ok,
                    (true, true) => Response::Refused(text("out-of-range")),
                };
                assert_eq!(
                    r.take(),
                    [RobotMsg::Response { id, resp: expect }],
                    "{name}={value} simulated={sim}"
                );
            }
            let cfg = r.runner.hopper().config();
            assert_eq!(cfg.supervisor.thermal.protect, !sim);
            assert_eq!(cfg.arming.untethered, sim);
        }
        // The safe value is taken on a robot.
        let mut r = Robot::new();
        let mut n = hopper_protocol::Name::new();
        let _ = n.push_str("thermal.protect");
        r.request(
            4,
            Request::ParamSet {
                name: n,
                value: 1.0,
            },
        );
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 4,
                resp: Response::Ok
            }]
        );
    }

    /// An arm or a routine in the same batch as a save, before the
    /// application took it (on the board, a reset follows), is refused.
    #[test]
    fn nothing_starts_while_a_save_is_queued() {
        let mut r = Robot::new();
        r.runner.arming_mut().note_tared();
        r.request(1, Request::Save);
        r.request(2, Request::Arm);
        r.periods(1);
        let msgs = r.take();
        assert_eq!(
            msgs.last(),
            Some(&RobotMsg::Response {
                id: 2,
                resp: Response::Refused(text("saving"))
            }),
            "{msgs:?}"
        );
        assert!(!r.runner.arming().is_armed());
    }

    /// A save behind an arm in the same batch is refused: the arm is
    /// decided at the next period, and the save's reset would follow it.
    #[test]
    fn no_save_while_an_arm_is_pending() {
        let mut r = Robot::new();
        r.runner.arming_mut().note_tared();
        r.request(1, Request::Arm);
        r.request(2, Request::Save);
        r.periods(1);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 2,
                resp: Response::Refused(text("arming"))
            }),
            "{msgs:?}"
        );
        assert!(r.ep.take_save().is_none());
    }

    /// A save needs a calibration (placeholders are none); once tared it is
    /// queued once for the application, and after a deferred save (the
    /// board's restart) nothing starts.
    #[test]
    fn a_save_needs_a_tare_and_is_taken_once() {
        let mut r = Robot::new();
        r.request(1, Request::Save);
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 1,
                resp: Response::Refused(text("not-calibrated"))
            }]
        );
        assert!(r.ep.take_save().is_none());
        r.runner.arming_mut().note_tared();
        r.request(2, Request::Save);
        r.periods(1);
        let _ = r.take();
        let n = r.ep.take_save().map(<[u8]>::len);
        assert_eq!(n, Some(7 + 13 * 8 + 2));
        assert!(r.ep.take_save().is_none());
        r.ep.save_done(true, true);
        r.request(3, Request::Arm);
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 3,
                resp: Response::Refused(text("restarting"))
            }]
        );
    }

    /// The scripted session of issue 17 at the library level (no transport):
    /// handshake, parameters, arm, a refused set, disarm, the e-stop, link
    /// loss and garbage on the line.
    #[test]
    fn a_scripted_session() {
        let mut r = Robot::new();
        r.send(&HostMsg::Hello {
            version: PROTOCOL_VERSION,
        });
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Hello {
                version: PROTOCOL_VERSION
            }]
        );
        r.periods(10);
        r.request(1, Request::ParamCount);
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 1,
                resp: Response::ParamCount(params::TABLE.len() as u16)
            }]
        );
        // Target 0.12 m and the shaped controller, while disarmed.
        r.request(
            2,
            Request::ParamSet {
                name: name("target_apex_m"),
                value: 0.12,
            },
        );
        r.request(
            3,
            Request::ParamSet {
                name: name("controller"),
                value: 8.0,
            },
        );
        r.periods(1);
        assert_eq!(
            r.take(),
            [
                RobotMsg::Response {
                    id: 2,
                    resp: Response::Ok
                },
                RobotMsg::Response {
                    id: 3,
                    resp: Response::Ok
                }
            ]
        );
        assert_eq!(r.runner.hopper().config().target_apex_m, 0.12);
        // The rebuilt controller's velocity filters measure after two
        // periods (`every_arm_request_is_answered` shows an earlier arm
        // refused).
        r.periods(2);
        // Arm: serviced after a period, decided and answered after the next.
        r.request(4, Request::Arm);
        r.periods(1);
        assert!(r.take().is_empty());
        let p = r.periods(1);
        assert!(p.armed);
        assert_eq!(
            r.take(),
            [
                RobotMsg::Response {
                    id: 4,
                    resp: Response::Ok
                },
                RobotMsg::State(ArmState::Armed)
            ]
        );
        // Out of range: refused, nothing changes.
        let cfg = *r.runner.hopper().config();
        r.request(
            5,
            Request::ParamSet {
                name: name("target_apex_m"),
                value: 2.0,
            },
        );
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 5,
                resp: Response::Refused(text("out-of-range"))
            }]
        );
        assert_eq!(*r.runner.hopper().config(), cfg);
        // Telemetry every period; disarm gives 0 A in the next record.
        r.request(6, Request::Telemetry { every: 1 });
        r.request(7, Request::Disarm);
        r.periods(1);
        r.take();
        r.periods(1);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::State(ArmState::Disarmed(2))),
            "{msgs:?}"
        );
        let t = msgs.iter().find_map(|m| match m {
            RobotMsg::Telemetry(t) => Some(*t),
            _ => None,
        });
        assert!(
            matches!(t, Some(t) if !t.armed && t.command_a == 0.0),
            "{t:?}"
        );
        // The e-stop pressed: arming refused with the reason.
        r.io.0.estop_pressed = true;
        r.periods(1);
        r.request(8, Request::Arm);
        r.periods(2);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 8,
                resp: Response::Refused(text("estop-pressed"))
            }),
            "{msgs:?}"
        );
        // The e-stop latched a fault: the capture freezes 64 / 4 = 16
        // periods later (holding every period since boot, fewer than 64),
        // and a dump streams it, oldest first, twice alike.
        let fault_step = r
            .capture
            .fault_step()
            .unwrap_or_else(|| panic!("no fault captured"));
        r.periods(20);
        assert!(r.capture.frozen());
        let held = r.capture.len();
        assert_eq!(held as u32, fault_step + 16);
        let mut dumps = Vec::new();
        for id in [20, 21] {
            r.take();
            r.request(id, Request::Dump);
            r.periods(40);
            let msgs = r.take();
            assert!(
                msgs.contains(&RobotMsg::Response {
                    id,
                    resp: Response::Dump(DumpInfo {
                        records: held as u16,
                        frozen: true,
                        fault_step
                    })
                }),
                "{msgs:?}"
            );
            let recs: Vec<Telemetry> = msgs
                .iter()
                .filter_map(|m| match m {
                    RobotMsg::Captured(t) => Some(*t),
                    _ => None,
                })
                .collect();
            assert_eq!(recs.len(), held);
            assert!(recs.iter().enumerate().all(|(i, t)| t.seq == i as u32));
            assert_eq!(recs[held - 1].step, fault_step + 16);
            dumps.push(recs);
        }
        assert_eq!(dumps[0], dumps[1]);
        // Released, faults reset, armed again; then no frame for 0.2 s:
        // disarmed by link loss within the timeout.
        // The release counts after 50 ms (`estop.release_s`).
        r.io.0.estop_pressed = false;
        r.periods(500);
        let _ = r.take();
        r.request(9, Request::ResetFaults);
        r.request(10, Request::Arm);
        r.periods(2);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 9,
                resp: Response::Ok
            }) && msgs.contains(&RobotMsg::State(ArmState::Armed)),
            "{msgs:?}"
        );
        let mut n = 0;
        while r.runner.arming().is_armed() {
            r.periods(1);
            n += 1;
            assert!(n <= 2002, "still armed");
        }
        assert!(n >= 1998, "disarmed after {n} periods");
        assert!(r.take().contains(&RobotMsg::State(ArmState::Disarmed(5))));
        // 1 KiB of garbage: counted, no fault, and the link still answers.
        let mut x: u32 = 0x1234_5678;
        let garbage: Vec<u8> = (0..1024)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                x as u8
            })
            .collect();
        r.receive(&garbage);
        r.receive(&[0]);
        r.request(11, Request::Status);
        r.periods(1);
        let msgs = r.take();
        let status = msgs.iter().find_map(|m| match m {
            RobotMsg::Response {
                id: 11,
                resp: Response::Status(s),
            } => Some(*s),
            _ => None,
        });
        let s = status.unwrap_or_else(|| panic!("{msgs:?}"));
        assert!(s.frames_bad > 0, "{s:?}");
        assert_eq!(s.faults, 0, "{s:?}");
    }
}
