//! Hardware in the loop, the host's end: the plant, sensor and amplifier
//! models here, the firmware on a robot image (`hopper-hil` on a board or
//! in QEMU, or [`HilTarget`] in this process), one exchange per control
//! period over the link.
//!
//! Each period the host sends the sensors' raw sample
//! ([`hopper_protocol::HilSample`], with a sequence number) and waits for
//! the answer ([`hopper_protocol::HilActuate`]: the DAC code and amplifier
//! enable the firmware wrote, the control interrupt's cost, and what a host
//! run reports of the firmware); the amplifier model then drives the plant
//! over the period. The host owns the clock: the run is as slow as the
//! line. A missing, repeated, out-of-order or corrupt answer stops the run
//! with an error (and nothing is written).
//!
//! Before the run the host configures the robot image through the link as
//! an operator would: every parameter of the run's configuration that
//! differs from the image's is set by name (`params::TABLE`), then the
//! robot is armed; the periods this takes run on the start sample, the body
//! held where it starts.

use crate::controller::{ContactTimes, EstimatorEvents, FaultRecord, PlantDriver, ThermalSummary};
use crate::plant::Plant;
use crate::sim_io::SimHal;
use hopper_control::hal::HopperIo;
use hopper_control::hopper::HopperConfig;
use hopper_control::params::{self, Param};
use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
use hopper_control::telemetry::{FaultCapture, HopLedger};
use hopper_protocol::vocab;
use hopper_protocol::{
    encode, Decoder, HilActuate, HilSample, HostMsg, Name, Request, Response, RobotMsg, MAX_FRAME,
    PROTOCOL_VERSION,
};
use hopper_robot_link::hil::{HilIo, NoPins};
use hopper_robot_link::{ControlLoop, Endpoint, Queues, Tx};
use serde::Serialize;
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// A byte line to a HIL target (a TCP socket, a serial port, an
/// in-process [`HilTarget`]) whose reads time out: a read that times out
/// is an error.
pub trait Line: Read + Write + Send {
    /// How long a read waits for a byte.
    fn set_timeout(&mut self, timeout: Duration) -> std::io::Result<()>;
}

impl Line for std::net::TcpStream {
    fn set_timeout(&mut self, timeout: Duration) -> std::io::Result<()> {
        self.set_read_timeout(Some(timeout))
    }
}

impl Line for Box<dyn serialport::SerialPort> {
    fn set_timeout(&mut self, timeout: Duration) -> std::io::Result<()> {
        serialport::SerialPort::set_timeout(self.as_mut(), timeout).map_err(std::io::Error::from)
    }
}

/// The line to a HIL target and how long the target may take to answer.
pub struct Connection {
    /// The line.
    pub line: Box<dyn Line>,
    /// The longest wait for an answer.
    pub timeout: Duration,
}

impl Connection {
    /// A HIL image's link on TCP (QEMU's `-serial tcp:...`), `HOST:PORT`.
    pub fn tcp(addr: &str, timeout: Duration) -> Result<Self, String> {
        let s = std::net::TcpStream::connect(addr)
            .map_err(|e| format!("HIL link at tcp {addr}: cannot connect: {e}"))?;
        // One small frame each way per period, each waited for: with
        // Nagle's algorithm against the robot's delayed ACK each would
        // wait 40 ms.
        s.set_nodelay(true)
            .map_err(|e| format!("HIL link at tcp {addr}: {e}"))?;
        Ok(Connection {
            line: Box::new(s),
            timeout,
        })
    }

    /// A HIL image's link on a serial port (a board's USB-UART).
    pub fn serial(port: &str, baud: u32, timeout: Duration) -> Result<Self, String> {
        let p = serialport::new(port, baud)
            .timeout(timeout)
            .open()
            .map_err(|e| format!("HIL link on serial {port}: cannot open: {e}"))?;
        Ok(Connection {
            line: Box::new(p),
            timeout,
        })
    }

    /// `tcp:HOST:PORT` or `serial:PORT` (at 921,600 baud), as the
    /// `HOPPER_HIL` environment variable names a HIL target for the SIL
    /// tests.
    pub fn named(target: &str, timeout: Duration) -> Result<Self, String> {
        match target.split_once(':') {
            Some(("tcp", addr)) => Self::tcp(addr, timeout),
            Some(("serial", port)) => Self::serial(port, 921_600, timeout),
            _ => Err(format!(
                "HIL target `{target}`: expected tcp:HOST:PORT or serial:PORT"
            )),
        }
    }
}

/// How often the hello is repeated until the robot answers: a robot still
/// booting (its USART not yet on) loses what arrives.
const HELLO_EVERY: Duration = Duration::from_millis(300);

/// Held periods a request may take before its answer is given up on (an
/// armed set or an arm is applied within a few).
const REQUEST_PERIODS: u32 = 200;

/// Held periods after the configuration, before the arm: the rate
/// filters' memory of a jump in what the sensors read decays by the filter
/// gain (0.9) each period, below the smallest `f32` within about 1,100.
const SETTLE_PERIODS: u32 = 2_000;

/// What a HIL run measured of the exchange and the robot's control
/// interrupt.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct HilReport {
    /// Periods of the run (the setup's held periods not included).
    pub periods: u64,
    /// Held periods before the run: configuring and arming the robot
    /// through the link.
    pub setup_periods: u64,
    /// Parameters set by name to configure the robot.
    pub params_set: usize,
    /// The robot's counter: `cycles` (a board: core cycles at
    /// `counter_hz`), `instructions` (QEMU) or `none` (an in-process
    /// target).
    pub isr_unit: &'static str,
    /// The robot's counter rate, Hz (0: instructions).
    pub counter_hz: u32,
    /// The control interrupt's cost per period over the run, mean.
    pub isr_mean: f64,
    /// Largest.
    pub isr_max: u32,
    /// Histogram of the cost: `[from, to)` and the periods in it.
    pub isr_histogram: Vec<(u32, u32, u64)>,
    /// Bytes per period, host to robot (mean).
    pub bytes_out_per_period: f64,
    /// Bytes per period, robot to host (mean, the hops' ledgers included).
    pub bytes_in_per_period: f64,
    /// Periods exchanged per wall-clock second.
    pub frames_per_s: f64,
    /// Simulated time over wall-clock time (below 1: slower than real
    /// time).
    pub realtime_factor: f64,
}

/// The host's end of a HIL run: drives the plant with what the robot
/// image's firmware answers.
pub struct HilDriver {
    name: &'static str,
    line: Box<dyn Line>,
    rx: Decoder,
    /// Bytes read and not yet decoded.
    pending: VecDeque<u8>,
    /// Answers to requests that came while waiting for a period's answer.
    responses: Vec<(u16, Response)>,
    next_id: u16,
    seq: u32,
    /// The sensor, DAC and amplifier models.
    pub hal: SimHal,
    dt_s: f64,
    target_apex_m: Option<f64>,
    faults: Vec<FaultRecord>,
    last_faults: u16,
    hops: Vec<HopLedger>,
    events: EstimatorEvents,
    contact_times: ContactTimes,
    arm_refusal: Option<&'static str>,
    thermal: ThermalSummary,
    max_abs_current_after_fault_a: Option<f64>,
    failure: Option<String>,
    isr: Vec<u32>,
    bytes_out: u64,
    bytes_in: u64,
    setup_periods: u64,
    params_set: usize,
    counter_hz: Option<u32>,
    started: Option<Instant>,
    /// Bad frames the decoder had counted when the session began (the
    /// handshake may meet a previous session's leftovers).
    bad_before: u32,
    injections: Vec<(crate::inject::Injection, crate::controller::InjectState)>,
}

impl HilDriver {
    /// Connects to the robot image on `connection`, configures it for `desired`
    /// (the configuration a host run of the same scenario runs), and arms
    /// it, holding the plant at its start (`plant`) meanwhile. `hal` is
    /// the sensor and amplifier models for `desired`'s calibration.
    pub fn connect(
        connection: Connection,
        desired: &HopperConfig,
        hal: SimHal,
        plant: &Plant,
        dt_s: f64,
        target_apex_m: Option<f64>,
        thermal: ThermalSummary,
    ) -> Result<Self, String> {
        let name = desired.strategy.kind().name();
        let Connection { line, timeout } = connection;
        let mut d = HilDriver {
            name,
            line,
            rx: Decoder::new(),
            pending: VecDeque::new(),
            responses: Vec::new(),
            // Not 1 every session: an answer to a request a killed session
            // left queued on the robot must not pass for one of this one's.
            next_id: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.subsec_nanos() as u16),
            seq: 0,
            hal,
            dt_s,
            target_apex_m,
            faults: Vec::new(),
            last_faults: 0,
            hops: Vec::new(),
            events: EstimatorEvents::default(),
            contact_times: ContactTimes::default(),
            arm_refusal: None,
            thermal,
            max_abs_current_after_fault_a: None,
            failure: None,
            isr: Vec::new(),
            bytes_out: 0,
            bytes_in: 0,
            setup_periods: 0,
            params_set: 0,
            counter_hz: None,
            started: None,
            bad_before: 0,
            injections: Vec::new(),
        };
        d.hello(timeout)?;
        // Sampled on a copy of the models: the run's own samples (and
        // their noise) are then a host run's, period for period.
        let held = d.hal.clone().sample(plant);
        // A target that ran before (the tests run one after another on
        // one image) may be armed: disarmed first.
        d.request(Request::Disarm, &held)?;
        d.configure(desired, &held)?;
        // A new calibration moves what the sensors read (the height
        // encoder's origin, for one): the rate filters (eq 4.1) saw a jump.
        // Held periods on the start sample let them forget it, to exactly
        // zero, before the arm checks that the robot is still, so the run
        // starts from the state a host run's firmware starts from.
        for _ in 0..SETTLE_PERIODS {
            d.exchange(&held)?;
            d.setup_periods += 1;
        }
        // Faults latched before (a previous run's, or the jump from its
        // last counts to this run's first) are cleared; a cause that
        // remains refuses the reset, and the arm then says why.
        d.request(Request::ResetFaults, &held)?;
        match d.request(Request::Arm, &held)? {
            Response::Ok => {}
            Response::Refused(r) => {
                // A code this host does not know (a newer robot) by number.
                d.arm_refusal = Some(
                    r.refusal()
                        .map_or("refused (a reason this host does not know)", |r| r.name()),
                );
            }
            other => return Err(format!("HIL target: arm answered {other:?}")),
        }
        // What ran so far was the setup; the run starts from here.
        d.isr.clear();
        d.bytes_out = 0;
        d.bytes_in = 0;
        d.last_faults = 0;
        Ok(d)
    }

    fn send(&mut self, msg: &HostMsg) -> Result<(), String> {
        let mut f = [0u8; MAX_FRAME];
        let n = encode(msg, &mut f).map_err(|e| format!("HIL: cannot frame {msg:?}: {e:?}"))?;
        self.line
            .write_all(&f[..n])
            .and_then(|()| self.line.flush())
            .map_err(|e| format!("HIL: the line failed while sending: {e}"))?;
        self.bytes_out += n as u64;
        Ok(())
    }

    /// The next message from the robot; a corrupt frame, a closed line or
    /// the read timeout is an error.
    fn recv(&mut self, waiting_for: &str) -> Result<RobotMsg, String> {
        loop {
            while let Some(b) = self.pending.pop_front() {
                self.bytes_in += 1;
                if let Some(m) = self.rx.push::<RobotMsg>(b) {
                    return Ok(m);
                }
                let bad = self.rx.stats().bad();
                if bad > self.bad_before {
                    return Err(format!(
                        "HIL: a corrupt frame from the robot while waiting for {waiting_for} ({:?}): the run stops",
                        self.rx.stats()
                    ));
                }
            }
            let mut buf = [0u8; 512];
            match self.line.read(&mut buf) {
                Ok(0) => {
                    return Err(format!(
                        "HIL: the robot closed the line while {waiting_for} was awaited"
                    ))
                }
                Ok(n) => self.pending.extend(&buf[..n]),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Err(format!(
                        "HIL: no answer from the robot for {waiting_for} (a lost frame, or the robot stopped): the run stops"
                    ))
                }
                Err(e) => return Err(format!("HIL: the line failed: {e}")),
            }
        }
    }

    /// The version handshake, repeated every [`HELLO_EVERY`] within the
    /// answer timeout `timeout`.
    fn hello(&mut self, timeout: Duration) -> Result<(), String> {
        let failed = |e: std::io::Error| format!("HIL: the line failed: {e}");
        let started = Instant::now();
        self.line.set_timeout(HELLO_EVERY).map_err(failed)?;
        let answered = loop {
            // Each attempt decodes afresh: what a previous session or a
            // booting robot left on the line is no error of this one.
            self.rx = Decoder::new();
            self.pending.clear();
            // A delimiter first flushes whatever a previous session left
            // on the line.
            self.line.write_all(&[0]).map_err(failed)?;
            self.send(&HostMsg::Hello {
                version: PROTOCOL_VERSION,
            })?;
            match self.recv("the robot's hello") {
                Ok(RobotMsg::Hello { version }) => break version,
                Ok(_) => {}
                Err(e) if started.elapsed() >= timeout => return Err(e),
                Err(_) => {}
            }
        };
        self.line.set_timeout(timeout).map_err(failed)?;
        self.bad_before = self.rx.stats().bad();
        if answered != PROTOCOL_VERSION {
            return Err(format!(
                "HIL: the robot speaks protocol {answered}, this host {PROTOCOL_VERSION}"
            ));
        }
        Ok(())
    }

    /// One period's exchange: sends `sample`, returns the robot's answer
    /// (answers to requests that arrive meanwhile are kept).
    fn exchange(&mut self, sample: &hopper_control::hal::RawSample) -> Result<HilActuate, String> {
        let seq = self.seq;
        self.send(&HostMsg::HilSample(HilSample {
            seq,
            motor_counts: sample.motor_counts,
            height_counts: sample.height_counts,
            loadcell_code: sample.loadcell_code,
            pot_code: sample.pot_code,
            estop_pressed: sample.estop_pressed,
            amp_fault: sample.amp_fault,
        }))?;
        let what = format!("sample {seq}");
        loop {
            match self.recv(&what)? {
                RobotMsg::HilActuate(a) if a.seq == seq => {
                    self.seq = seq.wrapping_add(1);
                    self.isr.push(a.isr_ticks);
                    return Ok(a);
                }
                RobotMsg::HilActuate(a) => {
                    return Err(format!(
                        "HIL: the answer to sample {} came while sample {seq}'s was awaited (a lost or repeated frame): the run stops",
                        a.seq
                    ))
                }
                RobotMsg::Response { id, resp } => self.responses.push((id, resp)),
                _ => {}
            }
        }
    }

    /// Sends `req` and runs held periods (on `held`) until its answer.
    fn request(
        &mut self,
        req: Request,
        held: &hopper_control::hal::RawSample,
    ) -> Result<Response, String> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        self.responses.clear();
        self.send(&HostMsg::Request {
            id,
            req: req.clone(),
        })?;
        for _ in 0..REQUEST_PERIODS {
            self.exchange(held)?;
            self.setup_periods += 1;
            if let Some(i) = self.responses.iter().position(|(i, _)| *i == id) {
                return Ok(self.responses.swap_remove(i).1);
            }
        }
        Err(format!(
            "HIL: no answer to {req:?} within {REQUEST_PERIODS} periods"
        ))
    }

    /// Sets every parameter of `desired` that differs on the robot, in the
    /// order [`configure_check`] checks (which refuses, before anything is
    /// sent, a configuration the link cannot reach).
    fn configure(
        &mut self,
        desired: &HopperConfig,
        held: &hopper_control::hal::RawSample,
    ) -> Result<(), String> {
        configure_check(desired)?;
        let mut want_cfg = *desired;
        for p in set_order() {
            let Ok(want) = params::read(&mut want_cfg, p) else {
                continue;
            };
            let name = wire_name(p)?;
            let have = match self.request(Request::ParamGet { name: name.clone() }, held)? {
                Response::Value(v) => Some(v),
                _ => None,
            };
            // The controller is always selected: that starts it from its
            // defaults, whatever a previous run left in it.
            let controller = p.name == params::CONTROLLER.name;
            if controller || have.map(f32::to_bits) != Some(want.to_bits()) {
                match self.request(Request::ParamSet { name, value: want }, held)? {
                    Response::Ok => self.params_set += 1,
                    Response::Refused(r) => {
                        return Err(format!("HIL: the robot refused {}={want}: {}", p.name, r))
                    }
                    other => return Err(format!("HIL: {} set answered {other:?}", p.name)),
                }
            }
        }
        Ok(())
    }

    /// With these sensor-side injections (`hopper-sim run --inject`).
    pub(crate) fn with_injections(
        mut self,
        injections: Vec<(crate::inject::Injection, crate::controller::InjectState)>,
    ) -> Self {
        self.injections = injections;
        self
    }

    /// What the run measured of the exchange.
    pub fn report(&mut self) -> HilReport {
        let periods = self.isr.len() as u64;
        let wall_s = self.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        // The run's figures before the question below adds its own frames.
        let (bytes_out, bytes_in) = (self.bytes_out, self.bytes_in);
        let isr = self.isr.clone();
        if self.counter_hz.is_none() {
            let held = self.hal.last_sample().unwrap_or_default();
            self.counter_hz = match self.request(Request::Cost, &held) {
                Ok(Response::Cost(c)) => Some(c.counter_hz),
                _ => Some(0),
            };
        }
        let counter_hz = self.counter_hz.unwrap_or(0);
        let max = isr.iter().copied().max().unwrap_or(0);
        let mean = if isr.is_empty() {
            0.0
        } else {
            isr.iter().map(|&v| f64::from(v)).sum::<f64>() / isr.len() as f64
        };
        HilReport {
            periods,
            setup_periods: self.setup_periods,
            params_set: self.params_set,
            isr_unit: match (max, counter_hz) {
                (0, _) => "none",
                (_, 0) => "instructions",
                _ => "cycles",
            },
            counter_hz,
            isr_mean: mean,
            isr_max: max,
            isr_histogram: histogram(&isr, 10),
            bytes_out_per_period: bytes_out as f64 / periods.max(1) as f64,
            bytes_in_per_period: bytes_in as f64 / periods.max(1) as f64,
            frames_per_s: if wall_s > 0.0 {
                periods as f64 / wall_s
            } else {
                0.0
            },
            realtime_factor: if wall_s > 0.0 {
                periods as f64 * self.dt_s / wall_s
            } else {
                0.0
            },
        }
    }
}

impl Drop for HilDriver {
    /// The run is over (or failed): the robot is asked to disarm (its
    /// deadman drops the enable anyway once the samples stop).
    fn drop(&mut self) {
        let id = self.next_id;
        let _ = self.send(&HostMsg::Request {
            id,
            req: Request::Disarm,
        });
    }
}

/// `p`'s name as the wire carries it.
fn wire_name(p: &Param) -> Result<Name, String> {
    let mut n = Name::new();
    n.push_str(p.name)
        .map_err(|_| format!("HIL: parameter name {} too long for the wire", p.name))?;
    Ok(n)
}

/// The parts of two configurations that differ, by name.
fn differing_parts(a: &HopperConfig, b: &HopperConfig) -> String {
    let mut parts = Vec::new();
    if a.calibration != b.calibration {
        parts.push("calibration: lead, torque constant or converter widths");
    }
    if a.supervisor != b.supervisor {
        parts.push("supervisor: the stops, stroke limits or current limit of the model");
    }
    if a.model != b.model {
        parts.push("the control model");
    }
    if parts.is_empty() {
        parts.push("a controller's or estimator's derived setting");
    }
    parts.join("; ")
}

/// `buckets` equal bins from 0 to the largest value.
fn histogram(v: &[u32], buckets: u32) -> Vec<(u32, u32, u64)> {
    let max = v.iter().copied().max().unwrap_or(0);
    let width = (max / buckets + 1).max(1);
    let mut out: Vec<(u32, u32, u64)> = (0..buckets)
        .map(|i| (i * width, (i + 1) * width, 0))
        .collect();
    for &x in v {
        let i = ((x / width) as usize).min(out.len() - 1);
        out[i].2 += 1;
    }
    out
}

impl PlantDriver for HilDriver {
    fn name(&self) -> &'static str {
        self.name
    }

    fn current_command_a(&mut self, plant: &Plant) -> f64 {
        if self.failure.is_some() {
            return 0.0;
        }
        self.started.get_or_insert_with(Instant::now);
        if !self.injections.is_empty() {
            crate::controller::apply_due_injections(
                &mut self.injections,
                &mut self.hal,
                plant,
                self.dt_s,
                &mut |_| {},
            );
        }
        let Ok(sample) = self.hal.sampled(plant).read() else {
            self.failure = Some("HIL: the sensor models gave no sample".to_string());
            return 0.0;
        };
        let a = match self.exchange(&sample) {
            Ok(a) => a,
            Err(e) => {
                self.failure = Some(e);
                return 0.0;
            }
        };
        // The simulated DAC refuses only under an injected fault, which a
        // HIL run does not take.
        let mut io = self.hal.io(plant);
        let _ = io.write_dac(a.dac_code);
        let _ = io.set_amp_enabled(a.amp_enabled);
        let t_s = plant.time_s();
        self.thermal.observe(
            t_s,
            f64::from(a.winding_c),
            f64::from(a.current_limit_a),
            a.derated,
        );
        let new = a.faults & !self.last_faults;
        self.last_faults = a.faults;
        // By the wire's vocabulary; a newer robot's unknown bits as one
        // "unknown".
        let (names, unknown) = vocab::Fault::names(new);
        let unknown = (unknown != 0).then_some("unknown");
        for name in names.chain(unknown) {
            self.faults.push(FaultRecord { name, time_s: t_s });
        }
        if let Some(h) = &a.hop {
            self.hops.push(hopper_robot_link::ledger_from_wire(h));
        }
        match vocab::PhaseEvent::from_code(a.event) {
            Some(vocab::PhaseEvent::Touchdown) => {
                self.events.touchdowns += 1;
                self.contact_times.touchdowns_s.push(t_s);
            }
            Some(vocab::PhaseEvent::Liftoff) => {
                self.events.liftoffs += 1;
                self.contact_times.liftoffs_s.push(t_s);
            }
            Some(vocab::PhaseEvent::Apex) => self.events.apexes += 1,
            _ => {}
        }
        self.events.withdrawn_touchdowns = a.withdrawn_touchdowns;
        if !self.faults.is_empty() {
            let i = self.hal.commanded_current_a().abs();
            let max = self.max_abs_current_after_fault_a.get_or_insert(0.0);
            *max = max.max(i);
        }
        self.hal.mean_current_a(self.dt_s)
    }

    fn failure(&self) -> Option<String> {
        self.failure.clone()
    }

    fn target_apex_m(&self) -> Option<f64> {
        self.target_apex_m
    }

    fn faults(&self) -> Vec<FaultRecord> {
        self.faults.clone()
    }

    fn max_abs_current_after_fault_a(&self) -> Option<f64> {
        self.max_abs_current_after_fault_a
    }

    fn hop_ledgers(&self) -> Vec<HopLedger> {
        self.hops.clone()
    }

    fn estimator_events(&self) -> Option<EstimatorEvents> {
        Some(self.events)
    }

    fn contact_times(&self) -> Option<ContactTimes> {
        Some(self.contact_times.clone())
    }

    fn thermal(&self) -> Option<ThermalSummary> {
        Some(self.thermal)
    }

    fn winding_c(&self) -> Option<f64> {
        Some(self.thermal.final_winding_c)
    }

    fn winding_resistance_ohm(&self) -> Option<f64> {
        Some(self.thermal.winding_resistance_ohm())
    }

    fn arm_refusal(&self) -> Option<&'static str> {
        self.arm_refusal
    }

    fn hil(&mut self) -> Option<HilReport> {
        Some(self.report())
    }
}

/// A HIL target in this process: the robot image's loop (the link's
/// endpoint, then a control period on each sample, then the answer) on a
/// byte line, as `hopper-hil` runs it on a board or in QEMU. For tests and
/// for the host reference of a HIL run.
pub struct HilTarget {
    firmware: ControlLoop,
    endpoint: Endpoint,
    queues: Queues,
    capture: FaultCapture<16>,
    io: HilIo<NoPins>,
    out: VecDeque<u8>,
    /// Frames from the host to drop (their index, from 0: the hello is
    /// frame 0), to test that a lost frame stops a run.
    pub drop_frames: Vec<u64>,
    frames_in: u64,
}

impl HilTarget {
    /// The HIL image's firmware ([`hopper_robot_link::hil::boot_config`])
    /// at `dt_s`, disarmed as at boot.
    pub fn new(dt_s: f64) -> Result<Self, String> {
        let timing = Timing {
            period_s: dt_s as f32,
            ..Timing::default()
        };
        let runner = PeriodRunner::new(hopper_robot_link::hil::boot_config(), timing)
            .map_err(|e| format!("HIL target configuration: {e:?}"))?;
        let endpoint = Endpoint::simulated(&runner);
        Ok(HilTarget {
            firmware: ControlLoop::new(runner),
            endpoint,
            queues: Queues::new(),
            capture: FaultCapture::new(),
            io: HilIo::new(NoPins),
            out: VecDeque::new(),
            drop_frames: Vec::new(),
            frames_in: 0,
        })
    }

    fn serve(&mut self, bytes: &[u8]) {
        let mut tx = OutBuf(&mut self.out);
        self.endpoint.serve(
            &mut self.queues,
            bytes.iter().copied(),
            &mut &mut self.capture,
            &mut tx,
            &mut NoCounter,
        );
    }
}

/// The target's transmit side: room without bound.
struct OutBuf<'a>(&'a mut VecDeque<u8>);

impl Tx for OutBuf<'_> {
    fn room(&self) -> usize {
        usize::MAX / 2
    }
    fn put(&mut self, frame: &[u8]) {
        self.0.extend(frame);
    }
}

impl Line for HilTarget {
    /// It answers at once: nothing to wait for.
    fn set_timeout(&mut self, _: Duration) -> std::io::Result<()> {
        Ok(())
    }
}

impl Write for HilTarget {
    /// Takes whole frames (the host writes one at a time) and runs what
    /// they ask, as the image's link task and control period would.
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        // A lone delimiter (the host's line flush) is no frame.
        if buf.len() > 1 {
            let index = self.frames_in;
            self.frames_in += 1;
            if self.drop_frames.contains(&index) {
                return Ok(buf.len());
            }
        }
        self.serve(buf);
        if let Some(s) = self.endpoint.take_hil_sample() {
            self.io.load(&s);
            let p = self.firmware.period(
                &mut self.io,
                &mut NoCounter,
                &mut &mut self.capture,
                &mut self.queues,
            );
            self.firmware.runner.end_period(false);
            let a = self.io.actuate(&p, &self.firmware.runner, 0);
            // The period's answers and notes first, then its actuation.
            self.serve(&[]);
            let mut tx = OutBuf(&mut self.out);
            self.endpoint.send_hil(&mut tx, &a);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Read for HilTarget {
    /// What the target sent; nothing waiting is a timeout (it answers at
    /// once, so nothing more will come).
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.out.is_empty() {
            return Err(std::io::Error::new(
                ErrorKind::TimedOut,
                "the target sent nothing",
            ));
        }
        let n = buf.len().min(self.out.len());
        for (b, o) in buf.iter_mut().zip(self.out.drain(..n)) {
            *b = o;
        }
        Ok(n)
    }
}

/// The order a whole configuration is set in over the link: the machine's
/// constants first (what follows from them, the supervisor's spring, the
/// calibration's lead, is then set as the run wants it), then the table's
/// order (the controller first: selecting one starts it from its defaults).
fn set_order() -> impl Iterator<Item = &'static params::Param> {
    params::MACHINE.iter().copied().chain(
        params::TABLE
            .iter()
            .copied()
            .filter(|p| !params::is_machine(p)),
    )
}

/// Whether the HIL image, from its boot configuration, becomes `desired`
/// by the link's sets alone: the error names the parts the link cannot set
/// (board facts: the counters' and converters' widths).
pub fn configure_check(desired: &HopperConfig) -> Result<(), String> {
    let mut want_cfg = *desired;
    let mut expected = hopper_robot_link::hil::boot_config();
    for p in set_order() {
        let Ok(want) = params::read(&mut want_cfg, p) else {
            continue;
        };
        params::set(&mut expected, p.name, want)
            .map_err(|e| format!("HIL: {} = {want}: {e:?}", p.name))?;
    }
    if expected != *desired {
        return Err(format!(
            "HIL: this run's firmware configuration differs from the HIL image's in what the link cannot set ({}): the HIL image's board facts (counter and converter widths) are fixed",
            differing_parts(&expected, desired)
        ));
    }
    Ok(())
}
