//! The robot's end of the host link (issue 17): what each
//! [`hopper_protocol`] message does to the [`PeriodRunner`], and what the
//! robot sends back. The transports (a UART interrupt, a TCP socket) only
//! move bytes: they feed a [`hopper_protocol::Decoder`], hand each decoded
//! [`HostMsg`] to [`Endpoint::on_message`] between two periods, and after
//! each period send what [`Endpoint::after_period`] yields. One
//! implementation, so the board, the QEMU image and the simulator's
//! virtual robot answer alike.
//!
//! - Every valid message keeps the link alive ([`crate::arming::Arming::link_frame`]).
//! - An arm request is decided at the next period; its response waits for
//!   that period (`Ok`, or `Refused` with the reason).
//! - Parameter sets go through [`PeriodRunner::set_param`].

use crate::arming::{ArmEvent, ArmState as RunnerArmState, DisarmReason};
use crate::params;
use crate::runner::{LogItem, Period, PeriodRunner};
use crate::supervisor::SupervisorInput;
use hopper_protocol::{
    ArmState, Hop, HostMsg, LinkStats, ParamInfo, Request, Response, RobotMsg, Status, Telemetry,
    PROTOCOL_VERSION, TEXT_LEN,
};

/// The robot's link state.
#[derive(Debug, Clone, Default)]
pub struct Endpoint {
    /// The id of an arm request waiting for the next period.
    pending_arm: Option<u16>,
    /// Telemetry every this many periods (0: off).
    every: u16,
    since: u16,
    seq: u32,
    telemetry_dropped: u32,
    last_apex_m: Option<f32>,
}

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
        RunnerArmState::Disarmed(r) => ArmState::Disarmed(match r {
            DisarmReason::Boot => 0,
            DisarmReason::WatchdogReset => 1,
            DisarmReason::Command => 2,
            DisarmReason::Estop => 3,
            DisarmReason::Fault => 4,
            DisarmReason::LinkLost => 5,
        }),
    }
}

impl Endpoint {
    /// No session yet, telemetry off.
    pub fn new() -> Self {
        Self::default()
    }

    /// Telemetry records the transmit queue could not take so far.
    pub fn telemetry_dropped(&self) -> u32 {
        self.telemetry_dropped
    }

    /// The transmit queue was full for a record: count it.
    pub fn drop_telemetry(&mut self) {
        self.telemetry_dropped = self.telemetry_dropped.saturating_add(1);
    }

    /// A decoded message, between periods: the answer to send now, if any
    /// (an arm request's comes with [`after_period`](Self::after_period)).
    /// `link` is the decoder's counts (for the status) and `rest` the
    /// supervisor input a fault reset is checked against (the latest
    /// measurements).
    pub fn on_message(
        &mut self,
        msg: &HostMsg,
        runner: &mut PeriodRunner,
        link: &LinkStats,
        rest: &SupervisorInput,
    ) -> Option<RobotMsg> {
        runner.arming_mut().link_frame();
        let (id, req) = match msg {
            HostMsg::Hello { .. } => {
                return Some(RobotMsg::Hello {
                    version: PROTOCOL_VERSION,
                })
            }
            HostMsg::Heartbeat => return None,
            HostMsg::Request { id, req } => (*id, req),
        };
        let resp = match req {
            Request::Status => Response::Status(self.status(runner, link)),
            Request::Arm => {
                runner.arming_mut().request_arm();
                self.pending_arm = Some(id);
                return None;
            }
            Request::Disarm => {
                runner.arming_mut().request_disarm();
                Response::Ok
            }
            Request::ResetFaults => match runner.reset_faults(rest) {
                Ok(()) => Response::Ok,
                Err(_) if runner.arming().is_armed() => Response::Refused(text("disarm-first")),
                Err(_) => Response::Refused(text("faults-remain")),
            },
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
                        live: p.live,
                    })
                }
                None => Response::Refused(text("no-such-index")),
            },
            Request::ParamGet { name } => match params::get(runner.hopper().config(), name) {
                Ok(v) => Response::Value(v),
                Err(_) => Response::Refused(text("unknown-parameter")),
            },
            Request::ParamSet { name, value } => match runner.set_param(name, *value) {
                Ok(()) => Response::Ok,
                Err(e) => Response::Refused(text(e.reason())),
            },
            Request::Telemetry { every } => {
                self.every = *every;
                self.since = 0;
                Response::Ok
            }
        };
        Some(RobotMsg::Response { id, resp })
    }

    /// After a period: the messages it produced, each given to `send` (the
    /// deferred arm answer, a state change, faults or a hop, a telemetry
    /// record when due). `send` returns `false` when its queue is full; a
    /// telemetry record it refuses is counted as dropped.
    pub fn after_period(&mut self, p: &Period, mut send: impl FnMut(RobotMsg) -> bool) {
        if let Some(ev) = p.arm_event {
            if let (Some(id), ArmEvent::Armed | ArmEvent::Refused(_)) = (self.pending_arm, ev) {
                self.pending_arm = None;
                let resp = match ev {
                    ArmEvent::Refused(r) => Response::Refused(text(r.name())),
                    _ => Response::Ok,
                };
                send(RobotMsg::Response { id, resp });
            }
            let state = match ev {
                ArmEvent::Armed => Some(ArmState::Armed),
                ArmEvent::Disarmed(r) => Some(arm_state(RunnerArmState::Disarmed(r))),
                ArmEvent::Refused(_) => None,
            };
            if let Some(s) = state {
                send(RobotMsg::State(s));
            }
        }
        match p.log {
            Some(LogItem::Faults { step, faults }) => {
                send(RobotMsg::Faults {
                    step,
                    bits: faults.0,
                });
            }
            Some(LogItem::Hop(h)) => {
                self.last_apex_m = Some(h.apex_height_m);
                send(RobotMsg::Hop(Hop {
                    hop: h.hop,
                    apex_height_m: h.apex_height_m,
                    energy_at_touchdown_j: h.energy_at_touchdown_j,
                    energy_at_liftoff_j: h.energy_at_liftoff_j,
                    stance_work_j: h.stance_work_j,
                    stance_duration_s: h.stance_duration_s,
                    peak_current_a: h.peak_current_a,
                    peak_stroke_m: h.peak_stroke_m,
                }));
            }
            None => {}
        }
        if self.every > 0 {
            self.since = self.since.saturating_add(1);
            if self.since >= self.every {
                self.since = 0;
                let r = p.out.record;
                let t = RobotMsg::Telemetry(Telemetry {
                    seq: self.seq,
                    step: r.step,
                    phase: r.phase,
                    armed: p.armed,
                    faults: r.faults,
                    body_height_m: r.body_height_m,
                    nut_position_m: r.nut_position_m,
                    spring_force_n: r.spring_force_n,
                    energy_j: r.energy_j,
                    command_a: r.command_a,
                });
                // The sequence number advances for a dropped record too:
                // the host sees the gap.
                self.seq = self.seq.wrapping_add(1);
                if !send(t) {
                    self.drop_telemetry();
                }
            }
        }
    }

    fn status(&self, runner: &PeriodRunner, link: &LinkStats) -> Status {
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

    /// A robot at rest behind a byte link: host bytes in, robot messages out.
    struct Robot {
        runner: PeriodRunner,
        io: Io,
        ep: Endpoint,
        rx: Decoder,
        rest: SupervisorInput,
        out: Vec<RobotMsg>,
    }

    impl Robot {
        fn new() -> Self {
            let cfg = HopperConfig::default();
            let raw = crate::proptest_support::rest_sample(&cfg.calibration);
            let rest = {
                let m = crate::calibration::Converter::new(cfg.calibration)
                    .and_then(|mut c| c.convert(&raw))
                    .unwrap_or_else(|e| panic!("{e:?}"));
                SupervisorInput::from_measurements(&m, 0.0, 0.0, 0.0)
            };
            Robot {
                runner: PeriodRunner::new(cfg, Timing::default())
                    .unwrap_or_else(|e| panic!("{e:?}")),
                io: Io(raw),
                ep: Endpoint::new(),
                rx: Decoder::new(),
                rest,
                out: Vec::new(),
            }
        }

        /// Host bytes arrive (between periods).
        fn receive(&mut self, bytes: &[u8]) {
            for &b in bytes {
                if let Some(m) = self.rx.push::<HostMsg>(b) {
                    let stats = self.rx.stats();
                    if let Some(r) = self.ep.on_message(&m, &mut self.runner, &stats, &self.rest) {
                        self.out.push(r);
                    }
                }
            }
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
                let out = &mut self.out;
                self.ep.after_period(&p, |m| {
                    out.push(m);
                    true
                });
                last = Some(p);
            }
            last.unwrap_or_else(|| panic!("no period"))
        }

        fn take(&mut self) -> Vec<RobotMsg> {
            core::mem::take(&mut self.out)
        }
    }

    fn name(s: &str) -> hopper_protocol::Name {
        let mut n = hopper_protocol::Name::new();
        let _ = n.push_str(s);
        n
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
        assert_eq!(
            r.take(),
            [RobotMsg::Hello {
                version: PROTOCOL_VERSION
            }]
        );
        r.periods(10);
        r.request(1, Request::ParamCount);
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
        // Arm: answered after the next period.
        r.request(4, Request::Arm);
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
        r.periods(1);
        let msgs = r.take();
        assert!(
            msgs.contains(&RobotMsg::Response {
                id: 8,
                resp: Response::Refused(text("estop-pressed"))
            }),
            "{msgs:?}"
        );
        // Released, faults reset, armed again; then no frame for 0.2 s:
        // disarmed by link loss within the timeout.
        r.io.0.estop_pressed = false;
        r.request(9, Request::ResetFaults);
        r.request(10, Request::Arm);
        r.periods(1);
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
