//! The link protocol between a host (`hopper-link`, tests) and a robot (the
//! board, the QEMU image, `hopper-sim serve`).
//!
//! `no_std` and allocation-free, so the firmware and the host share one
//! implementation:
//!
//! - messages are serde types ([`HostMsg`], [`RobotMsg`]) encoded with
//!   postcard;
//! - a frame is `COBS(postcard(message) ++ CRC-16/XMODEM(postcard bytes),
//!   little-endian)` followed by a single `0x00` delimiter ([`encode`]): COBS
//!   leaves no zero inside a frame, so a receiver finds frame boundaries
//!   after any garbage;
//! - [`Decoder`] takes bytes as they arrive (one at a time, from an
//!   interrupt, or in chunks) and yields whole messages; every frame that
//!   is too long, fails COBS, fails its CRC or does not decode is counted
//!   ([`LinkStats`]) and dropped, and decoding never panics on any input
//!   (a property test and the `link` fuzz target check it);
//! - the first exchange is a version handshake ([`HostMsg::Hello`],
//!   [`RobotMsg::Hello`], [`PROTOCOL_VERSION`]); requests carry an id that
//!   their response repeats; telemetry, hop ledgers, faults, state changes
//!   and log text come unsolicited, telemetry with a sequence number so
//!   the host counts drops.
#![no_std]
#![warn(missing_docs)]
#![deny(unsafe_code)]

pub mod vocab;

use serde::{Deserialize, Serialize};

/// The protocol version: a host and a robot talk only when theirs agree.
pub const PROTOCOL_VERSION: u16 = 5;

/// Largest encoded message, bytes (postcard, before the CRC and COBS).
pub const MAX_MESSAGE: usize = 120;

/// Largest frame on the wire, bytes: the message, 2 CRC bytes, COBS's
/// overhead (one byte per 254, plus one) and the delimiter.
pub const MAX_FRAME: usize = MAX_MESSAGE + 2 + MAX_MESSAGE / 254 + 2;

/// Longest parameter name carried, bytes (the table's longest is 40).
pub const NAME_LEN: usize = 48;

/// Longest log text carried, bytes.
pub const TEXT_LEN: usize = 64;

/// A parameter name on the wire.
pub type Name = heapless::String<NAME_LEN>;

/// CRC-16/XMODEM (polynomial 0x1021): two bytes per frame catch every
/// burst error up to 16 bits on a UART line.
const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_XMODEM);

/// CRC-16/XMODEM of `bytes`: the frames' check, and the saved
/// calibration's (`hopper_control::persist`).
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC.checksum(bytes)
}

/// Host to robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum HostMsg {
    /// Opens a session: the host's protocol version.
    Hello {
        /// [`PROTOCOL_VERSION`] of the host.
        version: u16,
    },
    /// Keeps the link alive (any valid frame does; this one carries nothing).
    Heartbeat,
    /// A request; the robot answers with a [`RobotMsg::Response`] with the same id.
    Request {
        /// Chosen by the host, repeated in the response.
        id: u16,
        /// What is asked.
        req: Request,
    },
    /// Hardware in the loop: the sensors' raw reading for one control
    /// period, from the host's plant and sensor models. A robot image
    /// built for it (`hopper-hil`) runs one period on it and answers
    /// [`RobotMsg::HilActuate`] with the same `seq`; every other robot
    /// ignores it. The host owns the clock: the period starts when the
    /// sample arrives.
    HilSample(HilSample),
}

/// What a host can ask.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// The robot's state ([`Response::Status`]).
    Status,
    /// Arm (refused with the reason unless every condition holds).
    Arm,
    /// Disarm.
    Disarm,
    /// Clear the latched faults (only while disarmed, and only when every
    /// one's cause is gone).
    ResetFaults,
    /// The number of parameters in the table.
    ParamCount,
    /// One table entry by index ([`Response::ParamInfo`]).
    ParamInfo {
        /// Index into the table.
        index: u16,
    },
    /// A parameter's value by name.
    ParamGet {
        /// The table name.
        name: Name,
    },
    /// Set a parameter; checked on the robot and applied at a period boundary.
    ParamSet {
        /// The table name.
        name: Name,
        /// The value, in the parameter's unit (flags 0/1, choices by index).
        value: f32,
    },
    /// Telemetry records every `every` periods (0: off).
    Telemetry {
        /// Decimation, periods per record.
        every: u16,
    },
    /// The control step's and the link's cost ([`Response::Timing`]).
    Timing,
    /// The capture around the last fault ([`Response::Dump`], then its
    /// records as [`RobotMsg::Captured`]).
    Dump,
    /// Presses or releases the simulated e-stop (the QEMU image and
    /// `hopper-sim serve`; a real robot refuses it: its e-stop is a button).
    SimulateEstop {
        /// Pressed.
        pressed: bool,
    },
    /// The motor's estimated temperatures ([`Response::Thermal`]).
    Thermal,
    /// What the board found at boot ([`Response::Boot`]).
    Boot,
    /// Starts a bring-up routine (`hopper_control::bringup::Routine` by
    /// code: 0 sensor check, 1 tare, 2 direction, 3 home, 4 spring, 5
    /// height) for `seconds` (the measuring ones; the motor-driving ones
    /// end when their moves are done); refused while armed.
    Calibrate {
        /// The routine's code.
        routine: u8,
        /// How long it measures, s.
        seconds: f32,
    },
    /// The last routine's report ([`Response::Calibration`]).
    CalibrationReport,
    /// What the last routine found ([`Response::BringupResults`]).
    BringupResults,
    /// Moves the simulated robot (the QEMU image and `hopper-sim serve`; a
    /// real robot refuses it): `hoisted` clamps the body where it is and
    /// lifts it to `lift_m` above where the toe leaves the ground (at 0.1
    /// m/s, so the encoders see a motion, not a jump); not `hoisted` lets
    /// go of it.
    SimulateMount {
        /// Held by the hoist.
        hoisted: bool,
        /// The toe's height to lift it to, m (with `hoisted`).
        lift_m: f32,
    },
    /// Saves the calibration (`hopper_control::persist`) to flash; refused
    /// while armed or calibrating. [`Request::Stored`] says how it went.
    Save,
    /// What was loaded at boot and how the last save went
    /// ([`Response::Stored`]).
    Stored,
    /// The crystal: the profile's and as measured at boot
    /// ([`Response::Crystal`]).
    Crystal,
    /// What the last weighing found ([`Response::Weighing`]).
    Weighing,
    /// What the control interrupt and the link task cost
    /// ([`Response::Cost`]).
    Cost,
    /// Where the motor's temperature estimate started at boot
    /// ([`Response::ThermalBoot`]).
    ThermalBoot,
    /// What a parameter is beyond its table entry: its kind, and which
    /// controller's configuration holds it ([`Response::ParamMeta`]).
    ParamMeta {
        /// The table name.
        name: Name,
    },
    /// The name of one value of a choice parameter ([`Response::Name`]).
    ParamChoice {
        /// The table name.
        name: Name,
        /// The value (the choice's index).
        value: u8,
    },
    /// Where the robot lost frames and bytes, and the requests it saw
    /// again ([`Response::LinkCounts`]).
    LinkCounts,
}

impl Request {
    /// Whether it acts on the robot: a repeat (a host's retry) is then
    /// answered from the robot's memory of its id, never run again; the
    /// others only read, and a repeat is answered afresh.
    pub fn acts(&self) -> bool {
        matches!(
            self,
            Request::Arm
                | Request::Disarm
                | Request::ResetFaults
                | Request::ParamSet { .. }
                | Request::Calibrate { .. }
                | Request::Save
                | Request::SimulateEstop { .. }
                | Request::SimulateMount { .. }
        )
    }
}

/// Robot to host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RobotMsg {
    /// Answers [`HostMsg::Hello`]: the robot's protocol version.
    Hello {
        /// [`PROTOCOL_VERSION`] of the robot.
        version: u16,
    },
    /// The answer to a request.
    Response {
        /// The request's id.
        id: u16,
        /// The answer.
        resp: Response,
    },
    /// One telemetry record (unsolicited, while streaming).
    Telemetry(Telemetry),
    /// A hop ended (the firmware's ledger).
    Hop(Hop),
    /// Faults latched: the fault bits (`hopper_control::supervisor::Fault`).
    Faults {
        /// Control period number.
        step: u32,
        /// All latched faults, one bit each.
        bits: u16,
    },
    /// The arming state changed.
    State(ArmState),
    /// A line of log text.
    Log(heapless::String<TEXT_LEN>),
    /// One record of a dump ([`Request::Dump`]): `seq` is its index in the
    /// dump, oldest first.
    Captured(Telemetry),
    /// Hardware in the loop: what one period did with a
    /// [`HostMsg::HilSample`].
    HilActuate(HilActuate),
    /// One telemetry record of the planar machine (unsolicited, while
    /// streaming: a planar robot sends these in place of
    /// [`RobotMsg::Telemetry`]).
    Planar(PlanarTelemetry),
}

/// One period of the planar machine as its firmware sees it: what the
/// cockpit draws (the hip, the body pitched, the leg to its toe) and the
/// speed against its command.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlanarTelemetry {
    /// Sequence number of the record (consecutive; a gap is a drop).
    pub seq: u32,
    /// Control period number.
    pub step: u32,
    /// Armed.
    pub armed: bool,
    /// The toe is on the ground.
    pub stance: bool,
    /// What the guard latched ([`vocab::PlanarFault`]'s code; 0: nothing).
    pub fault: u8,
    /// The hip's forward position along the boom, m.
    pub x_m: f32,
    /// The hip's height above the ground, m.
    pub z_m: f32,
    /// Body pitch, nose up positive, rad.
    pub pitch_rad: f32,
    /// Leg angle from the vertical, toe ahead positive, rad.
    pub leg_angle_rad: f32,
    /// Leg length, m.
    pub leg_length_m: f32,
    /// The hip's forward speed as the estimator has it, m/s.
    pub speed_mps: f32,
    /// The commanded forward speed, m/s.
    pub speed_command_mps: f32,
    /// The hip amplifier's commanded current, A.
    pub hip_current_a: f32,
    /// The leg amplifier's commanded current, A.
    pub leg_current_a: f32,
}

/// One period's raw sensor reading (`hopper_control::hal::RawSample`), for
/// hardware in the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct HilSample {
    /// Consecutive from 0: the robot answers each once, in order.
    pub seq: u32,
    /// Motor quadrature counter, raw.
    pub motor_counts: u32,
    /// Height quadrature counter, raw.
    pub height_counts: u32,
    /// Load-cell ADC code.
    pub loadcell_code: u16,
    /// Leg potentiometer ADC code.
    pub pot_code: u16,
    /// The simulated e-stop is pressed (the board's own e-stop input
    /// counts too: either one presses it).
    pub estop_pressed: bool,
    /// The simulated amplifier reports a fault.
    pub amp_fault: bool,
}

/// What one hardware-in-the-loop period did: the outputs for the host's
/// amplifier model and what a host run reports of the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HilActuate {
    /// The sample's `seq`.
    pub seq: u32,
    /// The DAC code written.
    pub dac_code: u16,
    /// The amplifier enable written.
    pub amp_enabled: bool,
    /// The control interrupt's cost this period, in the robot's counter's
    /// ticks (core cycles on a board; instructions in QEMU), the serial
    /// interrupts that preempted it left out.
    pub isr_ticks: u32,
    /// The phase estimator's event this period
    /// ([`vocab::PhaseEvent`] by code; 0: none).
    pub event: u8,
    /// Every latched fault, one bit each ([`vocab::Fault`]).
    pub faults: u16,
    /// Whether the period's output went out armed.
    pub armed: bool,
    /// The motor's estimated winding temperature, C.
    pub winding_c: f32,
    /// The current limit in force (the supervisor's, derated), A.
    pub current_limit_a: f32,
    /// The motor's heat derates the limit.
    pub derated: bool,
    /// Touchdowns withdrawn so far (predicted, not confirmed).
    pub withdrawn_touchdowns: u32,
    /// The hop that ended this period, if one did.
    pub hop: Option<Hop>,
}

/// The arming state on the wire (`hopper_control::arming`'s names as codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ArmState {
    /// Armed.
    Armed,
    /// Disarmed: `hopper_control::arming::DisarmReason` by index (boot 0,
    /// watchdog-reset 1, command 2, estop 3, fault 4, link-lost 5).
    Disarmed(u8),
}

/// An answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Response {
    /// Done.
    Ok,
    /// Refused, with the reason ([`vocab::Refusal`]'s code: an arm
    /// refusal, a parameter's, a routine's or the link's own).
    Refused(vocab::RefusalCode),
    /// The state.
    Status(Status),
    /// The table's size.
    ParamCount(u16),
    /// One table entry.
    ParamInfo(ParamInfo),
    /// A parameter's value.
    Value(f32),
    /// What the control step and the link cost.
    Timing(TimingStats),
    /// A dump follows: this many [`RobotMsg::Captured`] records.
    Dump(DumpInfo),
    /// The motor's estimated temperatures.
    Thermal(ThermalStatus),
    /// What the board found at boot.
    Boot(BootInfo),
    /// A bring-up routine's report.
    Calibration(CalibrationInfo),
    /// What the last bring-up routine found.
    BringupResults(BringupResults),
    /// The saved calibration's state.
    Stored(StoredInfo),
    /// The crystal.
    Crystal(CrystalInfo),
    /// What the last weighing found.
    Weighing(WeighingInfo),
    /// What the control interrupt and the link task cost.
    Cost(CostStats),
    /// Where the motor's temperature estimate started at boot.
    ThermalBoot(ThermalBootInfo),
    /// What a parameter is beyond its table entry.
    ParamMeta(ParamMeta),
    /// A name (a choice's value).
    Name(Name),
    /// Answers [`Request::LinkCounts`].
    LinkCounts(LinkCounts),
}

/// Every place the robot's end of the link can lose a frame or a byte,
/// and what it did with requests it saw again ([`Request::LinkCounts`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkCounts {
    /// Frames received intact.
    pub frames_ok: u32,
    /// Frames longer than [`MAX_FRAME`].
    pub too_long: u32,
    /// Frames that are not valid COBS.
    pub bad_cobs: u32,
    /// Frames whose CRC does not match.
    pub bad_crc: u32,
    /// Frames with a good CRC that are no message this robot knows.
    pub unknown_message: u32,
    /// Bytes the UART received while the last was still unread (its
    /// overrun flag); the board only.
    pub serial_overrun: u32,
    /// Bytes with a framing error (no stop bit where it belongs); the
    /// board only.
    pub serial_framing: u32,
    /// Bytes received with noise (the UART's noise flag); the board only.
    pub serial_noise: u32,
    /// Bytes dropped because the receive queue was full.
    pub serial_full: u32,
    /// Requests that act, received again (a host's retry) after they were
    /// answered: answered again from memory, not run again.
    pub repeats_answered: u32,
    /// Requests that act, received again while the first was still being
    /// carried out: dropped (the first's answer answers both).
    pub repeats_in_flight: u32,
    /// Requests the control period applied a second time (same id): the
    /// check that the two counts above hold; 0.
    pub applied_twice: u32,
    /// Telemetry records not sent (the transmit queue was full).
    pub telemetry_dropped: u32,
}

/// What a parameter is beyond its table entry ([`ParamInfo`]): everything a
/// host needs to show and explain it without a copy of the firmware's
/// table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParamMeta {
    /// Its index in the table ([`Request::ParamInfo`]).
    pub index: u16,
    /// Its kind ([`vocab::ParamKind`] by code).
    pub kind: u8,
    /// How many values a choice has (their names by
    /// [`Request::ParamChoice`]); 0 for the other kinds.
    pub choices: u8,
    /// The controller (a value of the `controller` choice) whose
    /// configuration holds it; `None` when every configuration has it.
    pub controller: Option<u8>,
    /// A choice of that controller it also needs: the choice's table index
    /// and the value it must have (`step_closed.min_compression_m` needs
    /// `step_closed.gain` normalised).
    pub needs: Option<(u16, u8)>,
}

/// Where the motor's temperature estimate started at boot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalBootInfo {
    /// The winding's estimate at boot, C.
    pub winding_c: f32,
    /// Assumed hot (the derating temperature): nothing of the motor's
    /// heat survives a reset or a power cycle on this robot. Otherwise the
    /// estimate started at ambient (a simulated motor, cold at start).
    pub assumed_hot: bool,
}

/// The cost of the robot's real-time work, in its counter's units: core
/// cycles on the board, guest instructions in QEMU (`counter_hz` 0), 0 on
/// the host simulator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CostStats {
    /// The counter's rate, Hz (0: it counts instructions, not time).
    pub counter_hz: u32,
    /// The whole control interrupt, entry to exit (read, step, write,
    /// publish, at most one command), mean.
    pub isr_mean: u32,
    /// The whole control interrupt, largest.
    pub isr_max: u32,
    /// The whole control interrupt, largest since the previous
    /// [`Request::Cost`].
    pub isr_max_recent: u32,
    /// The link task's work per call (decode, answer, encode), mean.
    pub link_mean: u32,
    /// The link task's work per call, largest.
    pub link_max: u32,
    /// The serial interrupt (a byte in or out), largest: it preempts the
    /// control interrupt, so a period's worst case is the control
    /// interrupt plus this times the bytes a period brings.
    pub serial_max: u32,
    /// Serial interrupts so far.
    pub serial_count: u32,
    /// The largest deviation of a period's start from the period, s (0
    /// where the counter does not count time).
    pub max_jitter_s: f32,
    /// Period notes the link task had no room for (telemetry gaps).
    pub notes_dropped: u32,
    /// What paces the periods ([`vocab::Pacing`] by code).
    pub pacing: u8,
    /// The last late period's number ([`NO_LATE_PERIOD`]: none so far).
    pub late_period: u32,
    /// How it was late ([`vocab::LateCause`] by code).
    pub late_cause: u8,
    /// For a late start, how far it was from the period, s (negative:
    /// early).
    pub late_jitter_s: f32,
    /// Serial interrupts from the end of the period before it to its end:
    /// what preempted it.
    pub late_serial: u32,
    /// Bytes the robot's serial line lost (a USART overrun, or a receive
    /// queue with no room).
    pub serial_lost: u32,
}

/// [`CostStats::late_period`] when no period was late.
pub const NO_LATE_PERIOD: u32 = u32::MAX;

/// What the weighing found (`hopper_control::bringup::Routine::Weight`): a
/// standing nut sweep, the body lifted and lowered on the spring; NaN where
/// it did not measure (no weighing yet, or it failed before the sweep).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeighingInfo {
    /// Where it is (`hopper_control::bringup::CalState` by code).
    pub state: u8,
    /// The robot's weight as the load cell read it, the mean force of the
    /// lift and the lowering, N.
    pub weight_n: f32,
    /// The weight the configuration gives, `(M + m_s) g`, N.
    pub configured_weight_n: f32,
    /// Half the difference of the lift's and the lowering's forces: the
    /// friction on the leg in stance, N.
    pub friction_n: f32,
    /// How far the body rose while the nut went down, m.
    pub body_rise_m: f32,
}

/// The crystal (`hopper_control::boot::BootReport`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CrystalInfo {
    /// What the clock profile names, Hz (0: no crystal, a virtual robot).
    pub expected_hz: u32,
    /// As measured against the internal oscillator at boot, Hz (0: not
    /// measured).
    pub measured_hz: u32,
    /// The measured crystal is the profile's, within the firmware's
    /// tolerance (otherwise arming is refused).
    pub matches: bool,
}

/// The saved calibration's state (`hopper_control::persist`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StoredInfo {
    /// At boot: 0 no flash store, 1 nothing saved, 2 loaded, 3 refused
    /// (`boot_error` says why).
    pub boot: u8,
    /// Why the saved record was refused (`hopper_control::persist::LoadError`
    /// by code), 0 otherwise.
    pub boot_error: u8,
    /// Parameters the loaded record set.
    pub entries: u8,
    /// The last save: 0 none since boot, 1 pending, 2 saved, 3 failed, 4
    /// pending until a restart (the board writes its flash in `init`).
    pub save: u8,
    /// How many parameters a save writes (the calibration's).
    pub saved_count: u8,
}

/// What the motor-driving and height routines found
/// (`hopper_control::bringup`); NaN where the routine does not measure it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BringupResults {
    /// The routine's code.
    pub routine: u8,
    /// Where it is (`hopper_control::bringup::CalState` by code).
    pub state: u8,
    /// Direction check: the nut's travel in the pulse, m (down positive).
    pub nut_travel_m: f32,
    /// Direction check: the load cell's change in the pulse, N.
    pub force_change_n: f32,
    /// Homing: where the upper stop was in the encoder's frame before it
    /// was zeroed there, m.
    pub nut_offset_m: f32,
    /// Spring sweep: the fitted rate, N/m.
    pub spring_rate_n_per_m: f32,
    /// Spring sweep: the fit's force at zero compression, N.
    pub spring_intercept_n: f32,
    /// Spring sweep: RMS of the residuals, N.
    pub fit_rms_n: f32,
    /// Spring sweep: points fitted.
    pub fit_points: u32,
    /// Spring sweep: the compressions' standard deviation, m.
    pub fit_span_m: f32,
    /// Height zero: the correction applied to the body height, m.
    pub height_offset_m: f32,
    /// Largest current commanded, A.
    pub peak_current_a: f32,
}

/// A bring-up routine's report (`hopper_control::bringup::CalReport`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibrationInfo {
    /// The routine's code.
    pub routine: u8,
    /// Where it is: 0 idle, 1 running, 2 done, 3 failed (moving), 4 failed
    /// (sensors), 5 failed (out of range).
    pub state: u8,
    /// Samples taken.
    pub samples: u32,
    /// Load-cell code: mean.
    pub loadcell_mean_code: f32,
    /// Load-cell code: standard deviation.
    pub loadcell_std_code: f32,
    /// Potentiometer code: mean.
    pub pot_mean_code: f32,
    /// Potentiometer code: standard deviation.
    pub pot_std_code: f32,
    /// Largest motor-counter change from the first sample, counts.
    pub motor_span_counts: u32,
    /// Largest height-counter change from the first sample, counts.
    pub height_span_counts: u32,
    /// The tare's load-cell offset, codes (NaN otherwise).
    pub loadcell_offset_code: f32,
    /// The tare's potentiometer offset, codes (NaN otherwise).
    pub pot_offset_code: f32,
}

/// What the board found at boot (`hopper_control::boot::BootReport`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BootInfo {
    /// Reset causes, one bit each (`hopper_control::boot::ResetCause`).
    pub resets: u8,
    /// The brown-out reset is on.
    pub brown_out_reset_on: bool,
    /// The core clock is the one the clock profile names.
    pub clock_as_configured: bool,
    /// The core clock running, Hz.
    pub sysclk_hz: u32,
}

/// The motor's thermal estimate (`hopper_control::thermal`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalStatus {
    /// Winding temperature, C.
    pub winding_c: f32,
    /// Housing temperature, C.
    pub housing_c: f32,
    /// The current limit allowed now, as a fraction of the amplifier's.
    pub limit_scale: f32,
    /// Winding temperature where the derating starts, C.
    pub derate_c: f32,
    /// Winding temperature that latches `overtemperature`, C.
    pub trip_c: f32,
    /// Whether the protection acts (`thermal.protect`).
    pub protect: bool,
}

/// The cost of the robot's periodic work, in its counter's ticks (the
/// board: CPU cycles; QEMU: guest instructions; the simulator: 0, not
/// measured).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimingStats {
    /// The control period, s.
    pub period_s: f32,
    /// Control periods run.
    pub periods: u32,
    /// Periods whose next trigger came before they finished.
    pub missed: u32,
    /// Control step (`Hopper::step`), mean.
    pub step_mean: u32,
    /// Control step, largest.
    pub step_max: u32,
    /// The link's work in a period (received bytes decoded and answered,
    /// the period's messages framed and queued), mean.
    pub link_mean: u32,
    /// The link's work in a period, largest.
    pub link_max: u32,
}

/// What a dump holds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DumpInfo {
    /// Records that follow.
    pub records: u16,
    /// Whether a fault froze the capture (otherwise it is the latest periods).
    pub frozen: bool,
    /// The period the first fault latched in (0 if none).
    pub fault_step: u32,
}

/// The robot's state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Arming.
    pub arm: ArmState,
    /// Latched fault bits.
    pub faults: u16,
    /// Control periods run.
    pub periods: u32,
    /// Frames received intact.
    pub frames_ok: u32,
    /// Frames dropped (any reason, [`LinkStats::bad`]).
    pub frames_bad: u32,
    /// Telemetry records not sent (the transmit queue was full).
    pub telemetry_dropped: u32,
    /// Last apex, m (NaN before the first).
    pub last_apex_m: f32,
}

/// One table entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamInfo {
    /// Table name.
    pub name: Name,
    /// Unit.
    pub unit: heapless::String<8>,
    /// Range.
    pub min: f32,
    /// Range.
    pub max: f32,
    /// Default.
    pub default: f32,
    /// Value now.
    pub value: f32,
    /// May be set while armed (the others only while disarmed).
    pub live: bool,
}

/// One telemetry record (the firmware's `StepRecord`, plus a sequence number).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Sequence number of the record (consecutive; a gap is a drop).
    pub seq: u32,
    /// Control period number.
    pub step: u32,
    /// Phase (0 flight, 1 stance).
    pub phase: u8,
    /// Armed.
    pub armed: bool,
    /// Latched fault bits.
    pub faults: u16,
    /// Body height, m.
    pub body_height_m: f32,
    /// Nut position, m.
    pub nut_position_m: f32,
    /// Spring force, N.
    pub spring_force_n: f32,
    /// Energy estimate, J.
    pub energy_j: f32,
    /// Commanded current, A.
    pub command_a: f32,
}

/// One hop's ledger (the firmware's `HopLedger`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Hop {
    /// Hop number.
    pub hop: u32,
    /// Apex toe height, m.
    pub apex_height_m: f32,
    /// Energy at touchdown, J.
    pub energy_at_touchdown_j: f32,
    /// Energy at liftoff, J.
    pub energy_at_liftoff_j: f32,
    /// Stance work, J.
    pub stance_work_j: f32,
    /// Stance duration, s.
    pub stance_duration_s: f32,
    /// Peak current, A.
    pub peak_current_a: f32,
    /// Peak nut stroke, m.
    pub peak_stroke_m: f32,
    /// The motor's copper loss over the hop, J.
    pub copper_loss_j: f32,
    /// Its part in stance, J.
    pub stance_copper_loss_j: f32,
}

/// Why a message could not be framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The message does not fit [`MAX_MESSAGE`] (or the output buffer).
    TooLong,
}

/// Frames `msg` into `out`: `COBS(postcard(msg) ++ crc) ++ [0]`. Returns the
/// frame's length.
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut raw = [0u8; MAX_MESSAGE + 2];
    let body = postcard::to_slice(msg, &mut raw[..MAX_MESSAGE])
        .map_err(|_| EncodeError::TooLong)?
        .len();
    let crc = CRC.checksum(raw.get(..body).ok_or(EncodeError::TooLong)?);
    raw.get_mut(body..body + 2)
        .ok_or(EncodeError::TooLong)?
        .copy_from_slice(&crc.to_le_bytes());
    let n = cobs::try_encode(raw.get(..body + 2).ok_or(EncodeError::TooLong)?, out)
        .map_err(|_| EncodeError::TooLong)?;
    *out.get_mut(n).ok_or(EncodeError::TooLong)? = 0;
    Ok(n + 1)
}

/// Counts of what the [`Decoder`] received.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames that decoded to a message.
    pub ok: u32,
    /// Frames longer than [`MAX_FRAME`].
    pub too_long: u32,
    /// Frames that are not valid COBS (or too short for a CRC).
    pub bad_cobs: u32,
    /// Frames whose CRC does not match.
    pub bad_crc: u32,
    /// Frames with a good CRC that do not decode as a message.
    pub bad_message: u32,
}

impl LinkStats {
    /// Every dropped frame.
    pub fn bad(&self) -> u32 {
        self.too_long
            .saturating_add(self.bad_cobs)
            .saturating_add(self.bad_crc)
            .saturating_add(self.bad_message)
    }
}

/// A streaming frame decoder for messages of type `T`. Bytes between a
/// frame's end and the next delimiter are one (bad) frame; empty frames
/// (two delimiters in a row) are ignored, so a sender may start with a
/// delimiter to flush the line.
#[derive(Debug, Clone)]
pub struct Decoder {
    buf: [u8; MAX_FRAME],
    len: usize,
    /// The current frame overflowed: drop it at its delimiter.
    overflow: bool,
    stats: LinkStats,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Decoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME],
            len: 0,
            overflow: false,
            stats: LinkStats {
                ok: 0,
                too_long: 0,
                bad_cobs: 0,
                bad_crc: 0,
                bad_message: 0,
            },
        }
    }

    /// What was received so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Takes one byte; returns a message when `byte` ends a good frame.
    pub fn push<T: for<'de> Deserialize<'de>>(&mut self, byte: u8) -> Option<T> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if overflow {
            self.stats.too_long = self.stats.too_long.saturating_add(1);
            return None;
        }
        if len == 0 {
            return None;
        }
        let mut raw = [0u8; MAX_FRAME];
        let frame = self.buf.get(..len)?;
        let Ok(n) = cobs::decode(frame, &mut raw).map(|r| r.frame_size()) else {
            self.stats.bad_cobs = self.stats.bad_cobs.saturating_add(1);
            return None;
        };
        let (Some(body), Some(tail)) = (
            n.checked_sub(2).and_then(|b| raw.get(..b)),
            n.checked_sub(2).and_then(|b| raw.get(b..n)),
        ) else {
            self.stats.bad_cobs = self.stats.bad_cobs.saturating_add(1);
            return None;
        };
        let mut crc = [0u8; 2];
        crc.copy_from_slice(tail);
        if CRC.checksum(body) != u16::from_le_bytes(crc) {
            self.stats.bad_crc = self.stats.bad_crc.saturating_add(1);
            return None;
        }
        match postcard::from_bytes::<T>(body) {
            Ok(msg) => {
                self.stats.ok = self.stats.ok.saturating_add(1);
                Some(msg)
            }
            Err(_) => {
                self.stats.bad_message = self.stats.bad_message.saturating_add(1);
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;
    use std::vec;
    use std::vec::Vec;

    fn frame<T: Serialize>(msg: &T) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME];
        let n = encode(msg, &mut out).unwrap_or_else(|e| panic!("{e:?}"));
        out[..n].to_vec()
    }

    fn decode_all<T: for<'de> Deserialize<'de>>(d: &mut Decoder, bytes: &[u8]) -> Vec<T> {
        bytes.iter().filter_map(|&b| d.push::<T>(b)).collect()
    }

    fn name(s: &str) -> Name {
        let mut n = Name::new();
        n.push_str(s)
            .unwrap_or_else(|e| panic!("name too long: {e:?}"));
        n
    }

    #[test]
    fn the_largest_messages_fit_a_frame() {
        let info = RobotMsg::Response {
            id: u16::MAX,
            resp: Response::ParamInfo(ParamInfo {
                name: name(&"x".repeat(NAME_LEN)),
                unit: heapless::String::try_from("A s/rad").unwrap_or_default(),
                min: -1.0,
                max: 1.0,
                default: 0.0,
                value: 0.5,
                live: true,
            }),
        };
        let log = RobotMsg::Log(
            heapless::String::try_from("y".repeat(TEXT_LEN).as_str()).unwrap_or_default(),
        );
        let set = HostMsg::Request {
            id: 7,
            req: Request::ParamSet {
                name: name(&"z".repeat(NAME_LEN)),
                value: f32::MAX,
            },
        };
        let counts = RobotMsg::Response {
            id: u16::MAX,
            resp: Response::LinkCounts(LinkCounts {
                frames_ok: u32::MAX,
                too_long: u32::MAX,
                bad_cobs: u32::MAX,
                bad_crc: u32::MAX,
                unknown_message: u32::MAX,
                serial_overrun: u32::MAX,
                serial_framing: u32::MAX,
                serial_noise: u32::MAX,
                serial_full: u32::MAX,
                repeats_answered: u32::MAX,
                repeats_in_flight: u32::MAX,
                applied_twice: u32::MAX,
                telemetry_dropped: u32::MAX,
            }),
        };
        for f in [frame(&info), frame(&log), frame(&set), frame(&counts)] {
            assert!(f.len() <= MAX_FRAME, "{}", f.len());
            assert_eq!(f.iter().filter(|b| **b == 0).count(), 1);
            assert_eq!(f.last(), Some(&0));
        }
        let t = RobotMsg::Telemetry(Telemetry {
            seq: u32::MAX,
            step: u32::MAX,
            phase: 1,
            armed: true,
            faults: u16::MAX,
            body_height_m: 0.6,
            nut_position_m: 0.01,
            spring_force_n: 300.0,
            energy_j: 60.0,
            command_a: 33.7,
        });
        // The link's budget: 1 kHz of full records at 921,600 baud
        // (92,160 bytes/s) needs frames of at most 92 bytes.
        let n = frame(&t).len();
        std::println!("telemetry frame: {n} bytes");
        assert!(n <= 40, "telemetry frame {n} bytes");
    }

    #[test]
    fn a_corrupted_byte_is_counted_and_the_next_frame_still_decodes() {
        let a = frame(&HostMsg::Heartbeat);
        let b = frame(&HostMsg::Request {
            id: 3,
            req: Request::Arm,
        });
        let mut bad = b.clone();
        bad[1] ^= 0x40;
        let mut d = Decoder::new();
        let mut stream = Vec::new();
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&a);
        stream.extend_from_slice(&b);
        let got: Vec<HostMsg> = decode_all(&mut d, &stream);
        assert_eq!(
            got,
            [
                HostMsg::Heartbeat,
                HostMsg::Request {
                    id: 3,
                    req: Request::Arm
                }
            ]
        );
        assert_eq!(d.stats().ok, 2);
        assert_eq!(d.stats().bad(), 1);
        // Too long: dropped at its delimiter, counted, and the line recovers.
        let mut long = std::vec![1u8; 3 * MAX_FRAME];
        long.push(0);
        long.extend_from_slice(&a);
        let got: Vec<HostMsg> = decode_all(&mut d, &long);
        assert_eq!(got, [HostMsg::Heartbeat]);
        assert_eq!(d.stats().too_long, 1);
    }

    fn host_msg() -> impl Strategy<Value = HostMsg> {
        let name = "[a-z_.]{0,48}".prop_map(|s| {
            let mut n = Name::new();
            let _ = n.push_str(&s);
            n
        });
        let req = prop_oneof![
            Just(Request::Status),
            Just(Request::Arm),
            Just(Request::Disarm),
            Just(Request::ResetFaults),
            Just(Request::ParamCount),
            Just(Request::Timing),
            Just(Request::Dump),
            Just(Request::Thermal),
            Just(Request::Boot),
            Just(Request::CalibrationReport),
            Just(Request::BringupResults),
            Just(Request::Save),
            Just(Request::Stored),
            Just(Request::Crystal),
            Just(Request::Weighing),
            Just(Request::Cost),
            Just(Request::ThermalBoot),
            Just(Request::LinkCounts),
            (any::<bool>(), any::<f32>())
                .prop_map(|(hoisted, lift_m)| Request::SimulateMount { hoisted, lift_m }),
            (any::<u8>(), any::<f32>())
                .prop_map(|(routine, seconds)| Request::Calibrate { routine, seconds }),
            any::<bool>().prop_map(|pressed| Request::SimulateEstop { pressed }),
            any::<u16>().prop_map(|index| Request::ParamInfo { index }),
            name.clone().prop_map(|name| Request::ParamGet { name }),
            (name, any::<f32>()).prop_map(|(name, value)| Request::ParamSet { name, value }),
            any::<u16>().prop_map(|every| Request::Telemetry { every }),
        ];
        prop_oneof![
            any::<u16>().prop_map(|version| HostMsg::Hello { version }),
            Just(HostMsg::Heartbeat),
            (any::<u16>(), req).prop_map(|(id, req)| HostMsg::Request { id, req }),
            (any::<[u32; 3]>(), any::<[u16; 2]>(), any::<[bool; 2]>()).prop_map(
                |(
                    [seq, motor_counts, height_counts],
                    [loadcell_code, pot_code],
                    [estop_pressed, amp_fault],
                )| {
                    HostMsg::HilSample(HilSample {
                        seq,
                        motor_counts,
                        height_counts,
                        loadcell_code,
                        pot_code,
                        estop_pressed,
                        amp_fault,
                    })
                }
            ),
        ]
    }

    /// A hardware-in-the-loop period's frames at their largest (every
    /// counter and code at its widest varint, a hop ending): what the
    /// line carries per period, which bounds the periods per second a
    /// baud rate allows (docs/hil.md).
    #[test]
    fn hil_frames_fit_and_their_size_is_known() {
        let sample = HostMsg::HilSample(HilSample {
            seq: u32::MAX,
            motor_counts: u32::MAX,
            height_counts: u32::MAX,
            loadcell_code: u16::MAX,
            pot_code: u16::MAX,
            estop_pressed: false,
            amp_fault: false,
        });
        let hop = Hop {
            hop: u32::MAX,
            apex_height_m: 0.05,
            energy_at_touchdown_j: 1.0,
            energy_at_liftoff_j: 1.0,
            stance_work_j: 1.0,
            stance_duration_s: 0.1,
            peak_current_a: 30.0,
            peak_stroke_m: 0.01,
            copper_loss_j: 60.0,
            stance_copper_loss_j: 20.0,
        };
        let actuate = |hop| {
            RobotMsg::HilActuate(HilActuate {
                seq: u32::MAX,
                dac_code: 4095,
                amp_enabled: true,
                isr_ticks: u32::MAX,
                event: 3,
                faults: u16::MAX,
                armed: true,
                winding_c: 100.0,
                current_limit_a: 33.0,
                derated: true,
                withdrawn_touchdowns: u32::MAX,
                hop,
            })
        };
        assert_eq!(frame(&sample).len(), 28);
        assert_eq!(frame(&actuate(None)).len(), 38);
        assert_eq!(frame(&actuate(Some(hop))).len(), 79);
        for m in [actuate(None), actuate(Some(hop))] {
            let mut d = Decoder::new();
            let got: Vec<RobotMsg> = decode_all(&mut d, &frame(&m));
            assert_eq!(got, [m]);
        }
    }

    /// A planar record at its widest (every counter at its widest varint)
    /// fits a frame and comes back as it went: at the cockpit's 100
    /// records a second it is 5.4 kB/s of the line.
    #[test]
    fn planar_records_fit_and_their_size_is_known() {
        let m = RobotMsg::Planar(PlanarTelemetry {
            seq: u32::MAX,
            step: u32::MAX,
            armed: true,
            stance: true,
            fault: 6,
            x_m: 12.5,
            z_m: 0.71,
            pitch_rad: -0.05,
            leg_angle_rad: 0.2,
            leg_length_m: 0.6,
            speed_mps: 1.0,
            speed_command_mps: 1.0,
            hip_current_a: -4.0,
            leg_current_a: 20.0,
        });
        let bytes = frame(&m);
        assert_eq!(bytes.len(), 54);
        assert!(bytes.len() <= MAX_FRAME);
        let mut d = Decoder::new();
        assert_eq!(decode_all::<RobotMsg>(&mut d, &bytes), [m]);
    }

    proptest! {
        /// Any message survives framing and a byte-by-byte decoder, also
        /// after garbage on the line (one bad frame at most, then intact).
        #[test]
        fn round_trip_after_garbage(
            msgs in proptest::collection::vec(host_msg(), 1..8),
            garbage in proptest::collection::vec(any::<u8>(), 0..300),
        ) {
            let mut d = Decoder::new();
            let _: Vec<HostMsg> = decode_all(&mut d, &garbage);
            let mut stream = std::vec![0u8];
            for m in &msgs {
                stream.extend_from_slice(&frame(m));
            }
            let got: Vec<HostMsg> = decode_all(&mut d, &stream);
            // NaN != NaN: compare as bytes.
            prop_assert_eq!(
                got.iter().map(frame).collect::<Vec<_>>(),
                msgs.iter().map(frame).collect::<Vec<_>>()
            );
        }

        /// Arbitrary bytes never panic, and every delimiter ends exactly one
        /// (possibly empty) frame: the counts add up.
        #[test]
        fn arbitrary_bytes_are_counted(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
            let mut d = Decoder::new();
            let ok = bytes.iter().filter_map(|&b| d.push::<RobotMsg>(b)).count();
            let s = d.stats();
            prop_assert_eq!(s.ok as usize, ok);
            let delimiters = bytes.iter().filter(|b| **b == 0).count();
            prop_assert!((s.ok + s.bad()) as usize <= delimiters);
        }
    }
}
