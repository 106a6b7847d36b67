//! The endpoint and the port together, as the board runs them: a robot at
//! rest behind a byte link.

extern crate std;
use super::*;
use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::{Hopper, HopperConfig};
use hopper_control::runner::{NoCounter, Timing};
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
pub(crate) struct VecTx {
    pub(crate) bytes: Vec<u8>,
    pub(crate) cap: usize,
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
/// out; the control period's port and the link task run one after the
/// other, as the simulator's do.
struct Robot {
    runner: PeriodRunner,
    io: Io,
    port: ControlPort,
    ep: Endpoint,
    q: Queues,
    capture: FaultCapture<64>,
    inbox: Vec<u8>,
    tx: VecTx,
    host: Decoder,
}

impl Robot {
    fn new() -> Self {
        Self::with(false)
    }

    fn with(simulated: bool) -> Self {
        let cfg = HopperConfig::default();
        let raw = hopper_control::hal::RawSample::at_rest(&cfg.calibration);
        let runner = PeriodRunner::new(cfg, Timing::default()).unwrap_or_else(|e| panic!("{e:?}"));
        let ep = if simulated {
            Endpoint::simulated(&runner)
        } else {
            Endpoint::new(&runner)
        };
        Robot {
            runner,
            io: Io(raw),
            port: ControlPort::new(),
            ep,
            q: Queues::default(),
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
            last = Some(self.period(false));
        }
        last.unwrap_or_else(|| panic!("no period"))
    }

    /// One period, `late` (its deadline missed), then the link task.
    fn period(&mut self, late: bool) -> Period {
        {
            let p = self.runner.run_period(&mut self.io, &mut NoCounter);
            self.runner.end_period(late);
            self.port.after_period(
                &mut self.runner,
                &p,
                &mut self.capture,
                &mut self.q.commands,
                &mut self.q.answers,
                &mut self.q.notes,
                &mut self.q.stats,
                &mut self.q.logs,
            );
            let inbox = core::mem::take(&mut self.inbox);
            self.ep.service(
                &mut self.q.notes,
                &mut self.q.stats,
                &mut self.q.logs,
                &mut self.q.answers,
                &mut self.q.commands,
                inbox.into_iter(),
                &mut &mut self.capture,
                &mut self.tx,
                &mut NoCounter,
            );
            p
        }
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
    // Decoded after a period, applied after the next, decided after
    // the third.
    r.request(1, Request::Arm);
    r.periods(3);
    r.take();
    assert!(r.runner.arming().is_armed());
    r.request(2, Request::Arm);
    r.periods(3);
    assert!(r.take().contains(&RobotMsg::Response {
        id: 2,
        resp: Response::Ok
    }));
    // A disarm and an arm in one batch: applied in their order, a
    // period apart, each answered.
    r.request(3, Request::Disarm);
    r.request(4, Request::Arm);
    r.periods(4);
    let msgs = r.take();
    for id in [3, 4] {
        assert!(
            msgs.contains(&RobotMsg::Response {
                id,
                resp: Response::Ok
            }),
            "{msgs:?}"
        );
    }
    r.request(7, Request::Disarm);
    r.periods(3);
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
    r.periods(4);
    let msgs = r.take();
    assert!(
        msgs.contains(&RobotMsg::Response {
            id: 6,
            resp: refused(Refusal::SensorsImplausible)
        }),
        "{msgs:?}"
    );
}

/// A real robot's endpoint refuses the simulated e-stop; a simulated
/// one takes it.
#[test]
fn only_a_simulated_robot_takes_the_simulated_estop() {
    for (sim, expect) in [
        (false, refused(Refusal::NotSimulated)),
        (true, Response::Ok),
    ] {
        let mut r = Robot::new();
        if sim {
            r.ep = Endpoint::simulated(&r.runner);
        }
        r.request(1, Request::SimulateEstop { pressed: true });
        r.periods(2);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id: 1,
                resp: expect
            }]
        );
        assert_eq!(r.port.sim_estop(), sim);
    }
}

/// A real robot's link refuses to switch a protection off (and takes
/// its safe value); a simulated robot takes both.
#[test]
fn a_robot_link_refuses_to_switch_protections_off() {
    for sim in [false, true] {
        let mut r = Robot::new();
        if sim {
            r.ep = Endpoint::simulated(&r.runner);
        }
        for (id, name, value) in [
            (1, "thermal.protect", 0.0),
            (2, "arming.untethered", 1.0),
            (3, "thermal.protect", f32::NAN),
        ] {
            let mut n = hopper_protocol::Name::new();
            let _ = n.push_str(name);
            r.request(id, Request::ParamSet { name: n, value });
            r.periods(2);
            let expect = match (sim, value.is_nan()) {
                (false, _) => refused(Refusal::ProtectionLocked),
                (true, false) => Response::Ok,
                (true, true) => refused(Refusal::OutOfRange),
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
    r.periods(2);
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
            resp: refused(Refusal::Saving)
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
            resp: refused(Refusal::Arming)
        }),
        "{msgs:?}"
    );
    assert!(r.ep.take_save().is_none());
}

/// A board that cannot write its flash safely (the hardware watchdog
/// option, a low supply) refuses the save with that reason when it is
/// asked, not after the restart; nothing is queued.
#[test]
fn a_save_the_board_cannot_write_is_refused_with_its_reason() {
    let mut r = Robot::new();
    r.runner.arming_mut().note_tared();
    for (id, why) in [
        (1, Refusal::HardwareWatchdogOption),
        (2, Refusal::SupplyLow),
    ] {
        r.ep.set_save_refusal(Some(why));
        r.request(id, Request::Save);
        r.periods(1);
        assert_eq!(
            r.take(),
            [RobotMsg::Response {
                id,
                resp: refused(why)
            }]
        );
        assert!(r.ep.take_save().is_none());
    }
    r.ep.set_save_refusal(None);
    r.request(3, Request::Save);
    r.periods(1);
    let _ = r.take();
    assert!(r.ep.take_save().is_some());
}

/// A request that acts, received again with its id (the host heard no
/// answer and sent it again), is answered from memory and not carried
/// out again: a late repeat of a set does not undo a later set, of an
/// arm does not arm again after a disarm, of a routine does not start
/// it again, of a save does not queue a second.
#[test]
fn a_repeated_request_is_answered_from_memory_and_not_run_again() {
    let mut r = Robot::with(true);
    let answer = |r: &mut Robot, id: u16| {
        r.take().into_iter().find_map(|m| match m {
            RobotMsg::Response { id: got, resp } if got == id => Some(resp),
            _ => None,
        })
    };
    let target =
        |r: &Robot| hopper_control::params::get(r.runner.hopper().config(), "target_apex_m");
    let counts = |r: &Robot| r.ep.link_counts();
    let set = |v: f32| Request::ParamSet {
        name: name("target_apex_m"),
        value: v,
    };
    // A set, a later one, then the first again: the later value stays.
    r.request(10, set(0.12));
    r.periods(3);
    assert_eq!(answer(&mut r, 10), Some(Response::Ok));
    r.request(11, set(0.13));
    r.periods(3);
    assert_eq!(answer(&mut r, 11), Some(Response::Ok));
    r.request(10, set(0.12));
    r.periods(3);
    assert_eq!(answer(&mut r, 10), Some(Response::Ok));
    assert_eq!(target(&r), Ok(0.13));
    assert_eq!(counts(&r).repeats_answered, 1);
    // Arm, disarm, the arm again: stays disarmed; then arm, the disarm
    // again: stays armed.
    r.request(20, Request::Arm);
    r.periods(3);
    assert_eq!(answer(&mut r, 20), Some(Response::Ok));
    r.request(21, Request::Disarm);
    r.periods(3);
    assert_eq!(answer(&mut r, 21), Some(Response::Ok));
    r.request(20, Request::Arm);
    r.periods(3);
    assert_eq!(answer(&mut r, 20), Some(Response::Ok));
    assert!(!r.runner.arming().is_armed());
    r.request(22, Request::Arm);
    r.periods(3);
    assert!(r.runner.arming().is_armed());
    r.request(21, Request::Disarm);
    r.periods(3);
    assert_eq!(answer(&mut r, 21), Some(Response::Ok));
    assert!(r.runner.arming().is_armed());
    r.request(23, Request::Disarm);
    r.periods(3);
    let _ = r.take();
    // Reset faults, again: the first answer, from memory.
    r.request(30, Request::ResetFaults);
    r.periods(3);
    let first = answer(&mut r, 30);
    assert!(first.is_some());
    r.request(30, Request::ResetFaults);
    r.periods(3);
    assert_eq!(answer(&mut r, 30), first);
    // A routine that ended, asked again: not started again.
    let routine = Request::Calibrate {
        routine: hopper_control::bringup::Routine::SensorCheck as u8,
        seconds: 0.05,
    };
    r.request(40, routine.clone());
    r.periods(3);
    assert_eq!(answer(&mut r, 40), Some(Response::Ok));
    assert!(r.runner.calibrating());
    let mut n = 0;
    while r.runner.calibrating() && n < 20_000 {
        r.periods(10);
        n += 10;
    }
    let _ = r.take();
    assert!(
        !r.runner.calibrating(),
        "the routine did not end in {n} periods"
    );
    r.request(40, routine);
    r.periods(3);
    assert_eq!(answer(&mut r, 40), Some(Response::Ok));
    assert!(!r.runner.calibrating());
    // A save taken, asked again: not queued again.
    r.runner.arming_mut().note_tared();
    r.request(50, Request::Save);
    r.periods(1);
    assert_eq!(answer(&mut r, 50), Some(Response::Ok));
    assert!(r.ep.take_save().is_some());
    r.request(50, Request::Save);
    r.periods(1);
    assert_eq!(answer(&mut r, 50), Some(Response::Ok));
    assert!(r.ep.take_save().is_none());
    let c = counts(&r);
    assert_eq!((c.repeats_answered, c.applied_twice), (6, 0), "{c:?}");
    // A repeat while the first is still being carried out: dropped,
    // the first's answer answers both.
    r.request(60, set(0.14));
    r.request(60, set(0.14));
    r.periods(3);
    let msgs = r.take();
    let answers = msgs
        .iter()
        .filter(|m| matches!(m, RobotMsg::Response { id: 60, .. }))
        .count();
    assert_eq!((answers, counts(&r).repeats_in_flight), (1, 1), "{msgs:?}");
    // A new session (its hello) starts its ids again.
    r.send(&HostMsg::Hello {
        version: PROTOCOL_VERSION,
    });
    r.request(10, set(0.11));
    r.periods(3);
    assert_eq!(answer(&mut r, 10), Some(Response::Ok));
    assert_eq!(target(&r), Ok(0.11));
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
            resp: refused(Refusal::NotCalibrated)
        }]
    );
    assert!(r.ep.take_save().is_none());
    r.runner.arming_mut().note_tared();
    r.request(2, Request::Save);
    r.periods(1);
    let _ = r.take();
    let n = r.ep.take_save().map(<[u8]>::len);
    assert_eq!(n, Some(7 + 27 * 8 + 2));
    assert!(r.ep.take_save().is_none());
    r.ep.save_done(true, true);
    r.request(3, Request::Arm);
    r.periods(1);
    assert_eq!(
        r.take(),
        [RobotMsg::Response {
            id: 3,
            resp: refused(Refusal::Restarting)
        }]
    );
}

/// The scripted link session (`tests/link-session.txt`) at the library
/// level (no transport):
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
    // Each built by the link task and installed a period apart.
    r.periods(3);
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
    // Arm: decoded after a period, applied after the next, decided
    // and answered after the third.
    r.request(4, Request::Arm);
    r.periods(2);
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
            resp: refused(Refusal::OutOfRange)
        }]
    );
    assert_eq!(*r.runner.hopper().config(), cfg);
    // Telemetry every period; disarm gives 0 A in the next record.
    r.request(6, Request::Telemetry { every: 1 });
    r.request(7, Request::Disarm);
    r.periods(2);
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
    r.periods(3);
    let msgs = r.take();
    assert!(
        msgs.contains(&RobotMsg::Response {
            id: 8,
            resp: refused(Refusal::EstopPressed)
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
    r.periods(4);
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

/// The control period applies at most one command a period, whatever
/// the link task queued, and publishes one note a period.
#[test]
fn the_port_applies_at_most_one_command_a_period() {
    let mut r = Robot::new();
    r.periods(1);
    let _ = r.take();
    for id in 1..=3 {
        r.request(id, Request::Boot);
    }
    // Decoded after this period: three commands queued.
    r.periods(1);
    assert_eq!(r.q.commands.len(), 3);
    for left in [2, 1, 0] {
        let p = r.runner.run_period(&mut r.io, &mut NoCounter);
        let notes = r.q.notes.len();
        r.port.after_period(
            &mut r.runner,
            &p,
            &mut r.capture,
            &mut r.q.commands,
            &mut r.q.answers,
            &mut r.q.notes,
            &mut r.q.stats,
            &mut r.q.logs,
        );
        assert_eq!(r.q.commands.len(), left);
        assert_eq!(r.q.notes.len(), notes + 1);
    }
    r.periods(1);
    let answered = r
        .take()
        .iter()
        .filter(|m| {
            matches!(
                m,
                RobotMsg::Response {
                    resp: Response::Boot(_),
                    ..
                }
            )
        })
        .count();
    assert_eq!(answered, 3);
}

/// A set's controller is built by the link task in a spare slot and
/// installed by exchanging slots: the running slot goes back to the
/// link task, the configuration changes once, and a set that finds no
/// spare is refused `busy` with nothing changed.
#[test]
fn a_set_is_installed_by_exchanging_slots() {
    let cfg = HopperConfig::default();
    let bank: &'static mut [Hopper; 2] = std::boxed::Box::leak(std::boxed::Box::new([
        Hopper::new(cfg).unwrap_or_else(|e| panic!("{e:?}")),
        Hopper::new(cfg).unwrap_or_else(|e| panic!("{e:?}")),
    ]));
    let [a, b] = bank;
    let running: *const Hopper = a;
    let spare: *const Hopper = b;
    let mut runner =
        PeriodRunner::in_slot(cfg, Timing::default(), a).unwrap_or_else(|e| panic!("{e:?}"));
    let mut ep = Endpoint::new(&runner).with_spares([b]);
    let mut port = ControlPort::new();
    let mut q: Queues<&'static mut Hopper> = Queues::new();
    let mut capture: FaultCapture<64> = FaultCapture::new();
    let mut io = Io(hopper_control::hal::RawSample::at_rest(&cfg.calibration));
    let mut tx = VecTx {
        bytes: Vec::new(),
        cap: 4096,
    };
    let mut frames = Vec::new();
    for (id, value) in [(1, 0.11), (2, 0.12)] {
        let mut f = [0u8; MAX_FRAME];
        let msg = HostMsg::Request {
            id,
            req: Request::ParamSet {
                name: name("flight.kp_a_per_rad"),
                value,
            },
        };
        let n = encode(&msg, &mut f).unwrap_or_else(|e| panic!("{e:?}"));
        frames.extend_from_slice(&f[..n]);
    }
    let gen0 = runner.config_gen();
    for k in 0..3 {
        let p = runner.run_period(&mut io, &mut NoCounter);
        port.after_period(
            &mut runner,
            &p,
            &mut capture,
            &mut q.commands,
            &mut q.answers,
            &mut q.notes,
            &mut q.stats,
            &mut q.logs,
        );
        let rx = if k == 0 {
            core::mem::take(&mut frames)
        } else {
            Vec::new()
        };
        ep.service(
            &mut q.notes,
            &mut q.stats,
            &mut q.logs,
            &mut q.answers,
            &mut q.commands,
            rx.into_iter(),
            &mut &mut capture,
            &mut tx,
            &mut NoCounter,
        );
    }
    // The first set took the one spare; the second found none.
    let mut host = Decoder::new();
    let msgs: Vec<RobotMsg> = tx.bytes.iter().filter_map(|&x| host.push(x)).collect();
    assert!(
        msgs.contains(&RobotMsg::Response {
            id: 1,
            resp: Response::Ok
        }),
        "{msgs:?}"
    );
    assert!(msgs.contains(&RobotMsg::Response {
        id: 2,
        resp: refused(Refusal::Busy)
    }));
    assert_eq!(runner.config_gen(), gen0.wrapping_add(1));
    let kp = params::get(runner.hopper().config(), "flight.kp_a_per_rad");
    assert_eq!(kp, Ok(0.11));
    // The running controller is the spare's slot; the old one is the
    // link task's spare now.
    assert!(core::ptr::eq(runner.hopper(), spare));
    assert_eq!(ep.spares.len(), 1);
    assert!(core::ptr::eq(&*ep.spares[0], running));
}

/// `status` says which period was late, how, and what preempted it
/// (the serial interrupts around it), what paces the periods, and the
/// bytes the serial line lost.
#[test]
fn the_link_names_the_last_late_period_and_the_serial_bytes_lost() {
    let mut r = Robot::new();
    // Two serial interrupts a period; period 150 misses its deadline,
    // with 40 interrupts in the period after it; 3 bytes lost by then.
    for k in 0..300u32 {
        let count = 2 * k + if k > 150 { 40 } else { 0 };
        r.port
            .set_serial_cost(500, count, if k > 150 { 3 } else { 0 });
        r.period(k == 150);
    }
    r.request(1, Request::Cost);
    r.periods(2);
    let msgs = r.take();
    let k = msgs
        .iter()
        .find_map(|m| match m {
            RobotMsg::Response {
                id: 1,
                resp: Response::Cost(k),
            } => Some(*k),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{msgs:?}"));
    assert_eq!(k.late_period, 150);
    assert_eq!(
        k.late_cause,
        hopper_protocol::vocab::LateCause::Deadline.code()
    );
    // From period 149's end to period 151's: 2 + 2 + 40.
    assert_eq!(k.late_serial, 44);
    assert_eq!(k.serial_lost, 3);
    // No counter: the simulator's pacing, no start check.
    assert_eq!(k.pacing, hopper_protocol::vocab::Pacing::NoClock.code());
}

/// A board starts the motor's estimate hot at every boot, and says so:
/// the host reads where it started.
#[test]
fn the_link_says_where_the_motor_estimate_started() {
    for hot in [false, true] {
        let mut r = Robot::new();
        if hot {
            r.runner.assume_motor_warm();
        }
        let derate_c = r
            .runner
            .hopper()
            .config()
            .supervisor
            .thermal
            .derate_winding_c;
        r.request(1, Request::ThermalBoot);
        r.periods(2);
        let msgs = r.take();
        let b = msgs.iter().find_map(|m| match m {
            RobotMsg::Response {
                id: 1,
                resp: Response::ThermalBoot(b),
            } => Some(*b),
            _ => None,
        });
        let b = b.unwrap_or_else(|| panic!("{msgs:?}"));
        assert_eq!(b.assumed_hot, hot);
        if hot {
            assert_eq!(b.winding_c, derate_c);
        } else {
            assert!(b.winding_c < derate_c - 50.0, "{b:?}");
        }
    }
}

/// A save's restart waits 0.2 s for the answer to go out, and never
/// resets an armed robot: it asks for a disarm and waits a period
/// more; and nothing arms once it is queued.
#[test]
fn a_restart_never_resets_an_armed_robot() {
    let mut r = Robot::new();
    r.request(1, Request::Arm);
    r.periods(3);
    assert!(r.runner.arming().is_armed());
    let _ = r.take();
    let mut c = CommandQueue::<Owned>::new();
    let _ = c.enqueue(Command::Restart);
    let p = r.runner.run_period(&mut r.io, &mut NoCounter);
    r.port.after_period(
        &mut r.runner,
        &p,
        &mut r.capture,
        &mut c,
        &mut r.q.answers,
        &mut r.q.notes,
        &mut r.q.stats,
        &mut r.q.logs,
    );
    // 0.2 s at 10 kHz.
    for _ in 0..1_999 {
        assert!(!r.port.restart_due(&mut r.runner));
    }
    // Due, but armed: a disarm asked for instead.
    assert!(!r.port.restart_due(&mut r.runner));
    assert!(r.runner.arming().disarm_pending());
    // An arm queued now is refused.
    let _ = c.enqueue(Command::Arm { id: 9 });
    let p = r.runner.run_period(&mut r.io, &mut NoCounter);
    assert!(!p.armed);
    r.port.after_period(
        &mut r.runner,
        &p,
        &mut r.capture,
        &mut c,
        &mut r.q.answers,
        &mut r.q.notes,
        &mut r.q.stats,
        &mut r.q.logs,
    );
    assert!(
        r.port.restart_due(&mut r.runner),
        "disarmed: the reset is due"
    );
    let mut was_refused = false;
    while let Some(a) = r.q.answers.dequeue() {
        if let Answer::Reply {
            id: Some(9), resp, ..
        } = a
        {
            was_refused = resp == refused(Refusal::Restarting);
        }
    }
    assert!(was_refused);
}

/// A save is the control period's configuration as the link task
/// knows it: with a change in flight (a set, a tare's results) it is
/// refused `busy`, and a routine's start queued in the same batch
/// refuses it as a running one.
#[test]
fn a_save_waits_for_the_changes_in_flight() {
    let mut r = Robot::new();
    r.runner.arming_mut().note_tared();
    r.periods(1);
    r.request(
        1,
        Request::ParamSet {
            name: name("target_apex_m"),
            value: 0.1,
        },
    );
    r.request(2, Request::Save);
    r.request(
        3,
        Request::Calibrate {
            routine: hopper_control::bringup::Routine::SensorCheck as u8,
            seconds: 0.05,
        },
    );
    r.request(4, Request::Save);
    r.periods(1);
    let msgs = r.take();
    for (id, why) in [(2, Refusal::Busy), (4, Refusal::Calibrating)] {
        assert!(
            msgs.contains(&RobotMsg::Response {
                id,
                resp: refused(why)
            }),
            "{id}: {msgs:?}"
        );
    }
    assert!(r.ep.take_save().is_none());
}
