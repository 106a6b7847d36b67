//! The robot's end of the host link: what each [`hopper_protocol`]
//! message does, and what the robot sends back, split in two so that the
//! control interrupt does only control.
//!
//! - [`ControlPort`] runs in the control period, right after
//!   [`PeriodRunner::run_period`]: it records the period into the fault
//!   capture, publishes a small [`Note`] of the period (the record, the
//!   arming events, the log item, the counters the link answers from),
//!   and applies **at most one** [`Command`] that the link task decoded,
//!   checked and prepared: an arm, a disarm, a fault reset, a live target
//!   change, a controller built outside the period and installed at the
//!   period boundary, a routine's start, a query of a few words. Its work
//!   is a few copies, bounded and alike every period.
//! - [`Endpoint`] is the link task, at a lower priority: it decodes the
//!   received bytes, answers from its copy of the configuration and the
//!   last note (status, parameters, timing, a dump), validates parameter
//!   sets and builds their controllers ([`PeriodRunner::prepare_at`]),
//!   builds a routine's results the same way, encodes every message and
//!   keeps the CRC work off the control priority.
//!
//! The two talk through three single-producer, single-consumer queues
//! ([`Inbox`], [`Outbox`]: `heapless::spsc` halves on the board, whole
//! queues where both run in one thread), so nothing is locked and nothing
//! waits: the board, the QEMU link image and the simulator's virtual
//! robot run this one mechanism, in two tasks or one after the other.
//!
//! - Every valid message keeps the link alive (a command carries it; with
//!   nothing to ask the task sends [`Command::Alive`]).
//! - An arm request is decided at the period after it is applied; its
//!   response waits for that period (`Ok`, or `Refused` with the reason).
//! - Nothing waits: a frame that finds the transmit queue without room is
//!   not sent. Telemetry and dump records leave room for one more frame,
//!   so answers and state changes still fit when the stream fills the
//!   line; a dropped telemetry record is counted (its sequence number is
//!   used anyway, so the host sees the gap). A command that finds the
//!   command queue full is refused `busy`.

#![cfg_attr(not(test), no_std)]

use hopper_control::arming::ArmRefusal;
use hopper_control::arming::{ArmEvent, ArmState as RunnerArmState, DisarmReason};
use hopper_control::bringup::CalRefusal;
use hopper_control::hal::HopperIo;
use hopper_control::hopper::HopperConfig;
use hopper_control::params;
use hopper_control::runner::SetError;
use hopper_control::runner::{
    CycleCounter, HopperSlot, LogItem, Owned, Period, PeriodRunner, Prepared, StepStats, Then,
};
use hopper_control::telemetry::{FaultCapture, StepRecord};
pub use hopper_protocol::vocab::Refusal;
use hopper_protocol::{
    encode, ArmState, CostStats, Decoder, DumpInfo, HilActuate, HilSample, Hop, HostMsg,
    LinkCounts, ParamInfo, Request, Response, RobotMsg, Status, StoredInfo, Telemetry,
    ThermalStatus, TimingStats, MAX_FRAME, PROTOCOL_VERSION,
};

mod endpoint;
pub mod hil;
pub mod planar;
mod port;
#[cfg(test)]
mod tests;
mod wire;

pub use endpoint::{Endpoint, SerialCounts};
pub use port::{ControlPort, DISARM_REASONS};
pub use wire::{
    arm_refusal, arm_state, cal_refusal, disarm_reason, ledger_from_wire, param_choice, param_meta,
    set_refusal, wire_hop, wire_record,
};
// The wire's forms, for the two ends.
use wire::{bringup_info, calibration_info, late_cause, pacing, refused, weighing_info};

/// The simulated hoist's lift of the toe above the ground, m: the range a
/// [`Request::SimulateMount`] takes.
pub const LIFT_RANGE_M: core::ops::RangeInclusive<f32> = 0.0..=0.5;

/// A transmit queue of bytes (the board's UART ring, a socket buffer).
pub trait Tx {
    /// Bytes it can take now.
    fn room(&self) -> usize;
    /// Appends `frame`; only called with `frame.len() <= room()`.
    fn put(&mut self, frame: &[u8]);
}

/// The receiving end of a queue between the control period and the link
/// task.
pub trait Inbox<T> {
    /// The oldest item, if any.
    fn take(&mut self) -> Option<T>;
}

/// The sending end of a queue between the control period and the link
/// task.
pub trait Outbox<T> {
    /// Items it can take now.
    fn room(&self) -> usize;
    /// Appends `item`, or gives it back when full.
    fn put(&mut self, item: T) -> Result<(), T>;
}

impl<T> Inbox<T> for heapless::spsc::Consumer<'_, T> {
    fn take(&mut self) -> Option<T> {
        self.dequeue()
    }
}

impl<T> Outbox<T> for heapless::spsc::Producer<'_, T> {
    fn room(&self) -> usize {
        self.capacity().saturating_sub(self.len())
    }
    fn put(&mut self, item: T) -> Result<(), T> {
        self.enqueue(item)
    }
}

impl<T, const N: usize> Inbox<T> for heapless::spsc::Queue<T, N> {
    fn take(&mut self) -> Option<T> {
        self.dequeue()
    }
}

impl<T, const N: usize> Outbox<T> for heapless::spsc::Queue<T, N> {
    fn room(&self) -> usize {
        self.capacity().saturating_sub(self.len())
    }
    fn put(&mut self, item: T) -> Result<(), T> {
        self.enqueue(item)
    }
}

/// Something shared with a task of higher priority, reached for a short,
/// bounded moment (the board: an RTIC resource lock; one thread: `&mut`).
pub trait Shared<T> {
    /// Runs `f` on it.
    fn with<R>(&mut self, f: impl FnOnce(&mut T) -> R) -> R;
}

impl<T> Shared<T> for &mut T {
    fn with<R>(&mut self, f: impl FnOnce(&mut T) -> R) -> R {
        f(self)
    }
}

/// Periods between two [`Command::Alive`]s at most (2 ms at 10 kHz, a
/// hundredth of the link timeout): a flood of frames costs the control
/// period one command in twenty.
const ALIVE_EVERY: u32 = 20;

/// Capacity of the command queue (link task to control period); a
/// `heapless::spsc::Queue` of `N` holds `N - 1`.
pub const COMMANDS: usize = 4;
/// Capacity of the answer queue (control period to link task).
pub const ANSWERS: usize = 8;
/// Capacity of the note queue: periods the link task may fall behind
/// before telemetry has gaps.
pub const NOTES: usize = 16;

/// Configuration changes the link task may have in flight.
const PENDING: usize = COMMANDS + 1;

/// Spare controller slots the link task holds (a bank's: the running one
/// and these two make three).
pub const SPARES: usize = 2;

/// The command queue's storage.
pub type CommandQueue<H = Owned> = heapless::spsc::Queue<Command<H>, COMMANDS>;
/// The answer queue's storage.
pub type AnswerQueue<H = Owned> = heapless::spsc::Queue<Answer<H>, ANSWERS>;
/// The note queue's storage.
pub type NoteQueue = heapless::spsc::Queue<Note, NOTES>;
/// The stats queue's storage.
pub type StatsQueue = heapless::spsc::Queue<Stats, 4>;
/// The log queue's storage: a period's log item (a hop ended, faults
/// latched), 36 bytes, a few a second.
pub type LogQueue = heapless::spsc::Queue<LogItem, 8>;

/// The three queues, for a robot whose control period and link task run
/// one after the other in one thread (the simulator, the QEMU link image).
#[derive(Debug)]
pub struct Queues<H = Owned> {
    /// Link task to control period.
    pub commands: CommandQueue<H>,
    /// Control period to link task: answers.
    pub answers: AnswerQueue<H>,
    /// Control period to link task: one note a period.
    pub notes: NoteQueue,
    /// Control period to link task: the slow figures.
    pub stats: StatsQueue,
    /// Control period to link task: log items.
    pub logs: LogQueue,
}

impl<H> Default for Queues<H> {
    fn default() -> Self {
        Self::new()
    }
}

impl<H> Queues<H> {
    /// Empty queues (a `const` for a static built in place).
    pub const fn new() -> Self {
        Self {
            commands: CommandQueue::new(),
            answers: AnswerQueue::new(),
            notes: NoteQueue::new(),
            stats: StatsQueue::new(),
            logs: LogQueue::new(),
        }
    }
}

/// The control period's ends of the five queues to the link task.
pub trait PortQueues<H> {
    /// Commands the link task prepared.
    type Commands: Inbox<Command<H>>;
    /// Answers to the link task.
    type Answers: Outbox<Answer<H>>;
    /// One note a period.
    type Notes: Outbox<Note>;
    /// The slow figures.
    type Stats: Outbox<Stats>;
    /// Log items.
    type Logs: Outbox<LogItem>;
    /// All five, for one period.
    #[allow(clippy::type_complexity)] // The five ends, named by the trait.
    fn ends(
        &mut self,
    ) -> (
        &mut Self::Commands,
        &mut Self::Answers,
        &mut Self::Notes,
        &mut Self::Stats,
        &mut Self::Logs,
    );
}

/// The link task's ends of the five queues.
pub trait LinkQueues<H> {
    /// Commands to the control period.
    type Commands: Outbox<Command<H>>;
    /// Answers from it.
    type Answers: Inbox<Answer<H>>;
    /// Its notes.
    type Notes: Inbox<Note>;
    /// Its slow figures.
    type Stats: Inbox<Stats>;
    /// Its log items.
    type Logs: Inbox<LogItem>;
    /// All five, for one service.
    #[allow(clippy::type_complexity)] // The five ends, named by the trait.
    fn ends(
        &mut self,
    ) -> (
        &mut Self::Commands,
        &mut Self::Answers,
        &mut Self::Notes,
        &mut Self::Stats,
        &mut Self::Logs,
    );
}

/// Whole queues serve both ends in turn (one thread: `hopper-sim serve`,
/// the tests).
impl<H> PortQueues<H> for Queues<H> {
    type Commands = CommandQueue<H>;
    type Answers = AnswerQueue<H>;
    type Notes = NoteQueue;
    type Stats = StatsQueue;
    type Logs = LogQueue;
    fn ends(
        &mut self,
    ) -> (
        &mut CommandQueue<H>,
        &mut AnswerQueue<H>,
        &mut NoteQueue,
        &mut StatsQueue,
        &mut LogQueue,
    ) {
        (
            &mut self.commands,
            &mut self.answers,
            &mut self.notes,
            &mut self.stats,
            &mut self.logs,
        )
    }
}

impl<H> LinkQueues<H> for Queues<H> {
    type Commands = CommandQueue<H>;
    type Answers = AnswerQueue<H>;
    type Notes = NoteQueue;
    type Stats = StatsQueue;
    type Logs = LogQueue;
    fn ends(
        &mut self,
    ) -> (
        &mut CommandQueue<H>,
        &mut AnswerQueue<H>,
        &mut NoteQueue,
        &mut StatsQueue,
        &mut LogQueue,
    ) {
        (
            &mut self.commands,
            &mut self.answers,
            &mut self.notes,
            &mut self.stats,
            &mut self.logs,
        )
    }
}

/// The control period's halves of split [`Queues`] (the board and the
/// QEMU link image, where the two ends run in two tasks).
pub struct PortEnds<'a, H> {
    commands: heapless::spsc::Consumer<'a, Command<H>>,
    answers: heapless::spsc::Producer<'a, Answer<H>>,
    notes: heapless::spsc::Producer<'a, Note>,
    stats: heapless::spsc::Producer<'a, Stats>,
    logs: heapless::spsc::Producer<'a, LogItem>,
}

/// The link task's halves of split [`Queues`].
pub struct LinkEnds<'a, H> {
    commands: heapless::spsc::Producer<'a, Command<H>>,
    answers: heapless::spsc::Consumer<'a, Answer<H>>,
    notes: heapless::spsc::Consumer<'a, Note>,
    stats: heapless::spsc::Consumer<'a, Stats>,
    logs: heapless::spsc::Consumer<'a, LogItem>,
}

impl<H> Queues<H> {
    /// The control period's and the link task's ends, for two tasks.
    pub fn split(&mut self) -> (PortEnds<'_, H>, LinkEnds<'_, H>) {
        let (commands_in, commands_out) = self.commands.split();
        let (answers_in, answers_out) = self.answers.split();
        let (notes_in, notes_out) = self.notes.split();
        let (stats_in, stats_out) = self.stats.split();
        let (logs_in, logs_out) = self.logs.split();
        (
            PortEnds {
                commands: commands_out,
                answers: answers_in,
                notes: notes_in,
                stats: stats_in,
                logs: logs_in,
            },
            LinkEnds {
                commands: commands_in,
                answers: answers_out,
                notes: notes_out,
                stats: stats_out,
                logs: logs_out,
            },
        )
    }
}

impl<'a, H> PortQueues<H> for PortEnds<'a, H> {
    type Commands = heapless::spsc::Consumer<'a, Command<H>>;
    type Answers = heapless::spsc::Producer<'a, Answer<H>>;
    type Notes = heapless::spsc::Producer<'a, Note>;
    type Stats = heapless::spsc::Producer<'a, Stats>;
    type Logs = heapless::spsc::Producer<'a, LogItem>;
    fn ends(
        &mut self,
    ) -> (
        &mut Self::Commands,
        &mut Self::Answers,
        &mut Self::Notes,
        &mut Self::Stats,
        &mut Self::Logs,
    ) {
        (
            &mut self.commands,
            &mut self.answers,
            &mut self.notes,
            &mut self.stats,
            &mut self.logs,
        )
    }
}

impl<'a, H> LinkQueues<H> for LinkEnds<'a, H> {
    type Commands = heapless::spsc::Producer<'a, Command<H>>;
    type Answers = heapless::spsc::Consumer<'a, Answer<H>>;
    type Notes = heapless::spsc::Consumer<'a, Note>;
    type Stats = heapless::spsc::Consumer<'a, Stats>;
    type Logs = heapless::spsc::Consumer<'a, LogItem>;
    fn ends(
        &mut self,
    ) -> (
        &mut Self::Commands,
        &mut Self::Answers,
        &mut Self::Notes,
        &mut Self::Stats,
        &mut Self::Logs,
    ) {
        (
            &mut self.commands,
            &mut self.answers,
            &mut self.notes,
            &mut self.stats,
            &mut self.logs,
        )
    }
}

/// A queue end that leads nowhere: nothing arrives, and whatever is put
/// is dropped.
#[derive(Debug, Default)]
pub struct Nowhere;

impl<T> Inbox<T> for Nowhere {
    fn take(&mut self) -> Option<T> {
        None
    }
}

impl<T> Outbox<T> for Nowhere {
    fn room(&self) -> usize {
        usize::MAX
    }
    fn put(&mut self, _: T) -> Result<(), T> {
        Ok(())
    }
}

/// No link (a run with no host: `hopper-sim run`, the QEMU scenario
/// image): no command comes, and what the port publishes goes nowhere.
#[derive(Debug, Default)]
pub struct Unlinked([Nowhere; 5]);

impl<H> PortQueues<H> for Unlinked {
    type Commands = Nowhere;
    type Answers = Nowhere;
    type Notes = Nowhere;
    type Stats = Nowhere;
    type Logs = Nowhere;
    fn ends(
        &mut self,
    ) -> (
        &mut Nowhere,
        &mut Nowhere,
        &mut Nowhere,
        &mut Nowhere,
        &mut Nowhere,
    ) {
        let [c, a, n, s, l] = &mut self.0;
        (c, a, n, s, l)
    }
}

/// The one loop around the period runner: the board, both QEMU images,
/// the virtual robot (`hopper-sim serve`, the link tests) and `hopper-sim
/// run` run every control period as [`ControlLoop::period`]: read, step,
/// write ([`PeriodRunner::run_period`]), then the port
/// ([`ControlPort::after_period`]: the period into the capture, its note
/// published, at most one command applied). What differs is around it:
/// what paces the period, what the caller times, who services the link.
pub struct ControlLoop<H = Owned> {
    /// The period runner.
    pub runner: PeriodRunner<H>,
    /// The link's end in the control period.
    pub port: ControlPort,
}

impl<H: HopperSlot> ControlLoop<H> {
    /// The loop of `runner` (built disarmed), with a fresh port.
    pub fn new(runner: PeriodRunner<H>) -> Self {
        Self {
            runner,
            port: ControlPort::new(),
        }
    }

    /// One control period on `io`, timed with `counter`; the capture is
    /// reached through `capture` (the board: a lock of the control
    /// priority), the link task through `queues`.
    pub fn period<Io: HopperIo, C: CycleCounter, const N: usize>(
        &mut self,
        io: &mut Io,
        counter: &mut C,
        capture: &mut impl Shared<FaultCapture<N>>,
        queues: &mut impl PortQueues<H>,
    ) -> Period {
        let p = self.runner.run_period(io, counter);
        let (commands, answers, notes, stats, logs) = queues.ends();
        let (runner, port) = (&mut self.runner, &mut self.port);
        capture.with(|c| port.after_period(runner, &p, c, commands, answers, notes, stats, logs));
        p
    }
}

/// A query answered in the control period: a copy of a few words.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Query {
    /// [`Request::Boot`].
    Boot,
    /// [`Request::Crystal`].
    Crystal,
    /// [`Request::Stored`].
    Stored,
    /// [`Request::CalibrationReport`].
    CalibrationReport,
    /// [`Request::BringupResults`].
    BringupResults,
    /// [`Request::Weighing`].
    Weighing,
    /// [`Request::ThermalBoot`].
    ThermalBoot,
}

/// What the link task asks of the control period (at most one applied a
/// period, each a bounded amount of work). Every command also counts as a
/// frame received (the link timer).
// No allocator to box the controller in: a queue slot holds the largest
// variant, and the port copies one slot out in a period.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Command<H = Owned> {
    /// A valid frame arrived (nothing else asked).
    Alive,
    /// [`Request::Arm`]: decided at the next period, answered then.
    Arm {
        /// The request's id.
        id: u16,
    },
    /// [`Request::Disarm`].
    Disarm {
        /// The request's id.
        id: u16,
    },
    /// [`Request::ResetFaults`] (the capture rearms with it).
    ResetFaults {
        /// The request's id.
        id: u16,
    },
    /// A parameter that changes in place ([`PeriodRunner::set_live`]).
    SetLive {
        /// The request's id.
        id: u16,
        /// The configuration generation it was checked on (another, and
        /// it is refused: the change it folds in may not have run).
        base_gen: u32,
        /// The parameter.
        param: &'static params::Param,
        /// Its new value.
        value: f32,
    },
    /// A controller built by the link task, installed at the period
    /// boundary ([`PeriodRunner::install`]).
    Install {
        /// The request's id (`None`: a routine's results).
        id: Option<u16>,
        /// The controller, in its slot.
        prepared: Prepared<H>,
        /// What it completes.
        then: Then,
    },
    /// A routine's results could not be built: the routine fails.
    RebuildFailed,
    /// [`Request::Calibrate`], its routine known.
    Calibrate {
        /// The request's id.
        id: u16,
        /// The routine.
        routine: hopper_control::bringup::Routine,
        /// How long it measures, s.
        seconds: f32,
    },
    /// A query answered from the runner's state.
    Query {
        /// The request's id.
        id: u16,
        /// What.
        what: Query,
    },
    /// A save waits in the flash's RAM slot for the next boot: reset in
    /// 0.2 s ([`ControlPort::restart_due`]), never while armed.
    Restart,
    /// [`Request::SimulateEstop`] on a simulated robot: the sensor models
    /// read it from the port ([`ControlPort::sim_estop`]).
    SimulateEstop {
        /// The request's id.
        id: u16,
        /// Pressed.
        pressed: bool,
    },
    /// [`Request::SimulateMount`] on a simulated robot (checked): the
    /// plant takes it from the port ([`ControlPort::take_sim_mount`]).
    SimulateMount {
        /// The request's id.
        id: u16,
        /// Held by the hoist.
        hoisted: bool,
        /// The toe height to lift to, m.
        lift_m: f32,
    },
}

/// What the control period sends the link task besides its notes.
// As [`Command`]: a slot holds the largest variant either way.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Answer<H = Owned> {
    /// A command's answer, for the host (`None`: a routine's install,
    /// for the link task only).
    Reply {
        /// The request's id.
        id: Option<u16>,
        /// The answer.
        resp: Response,
        /// It answers a change of the configuration (an install or a live
        /// change) that the link task counted in flight.
        set: bool,
    },
    /// A slot an install freed, for the link task's next controller.
    Spare(H),
    /// A routine's results need a controller: the configuration with
    /// `changes`.
    Rebuild {
        /// The generation it is built on.
        generation: u32,
        /// The parameters it changes.
        changes: hopper_control::runner::Changes,
        /// What the install completes.
        then: Then,
    },
}

/// One period, as the link task sees it (a copy of 48 bytes: a log item,
/// a few a second, goes in a queue of its own).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Note {
    /// The period's record (its step number, faults, measurements).
    pub record: StepRecord,
    /// What arming did.
    pub arm_event: Option<ArmEvent>,
    /// The arming state after the period.
    pub arm: RunnerArmState,
    /// An arm request waits for the next period.
    pub arm_pending: bool,
    /// A bring-up routine runs (or its results wait to be installed).
    pub calibrating: bool,
    /// A tare (or a loaded record) stands.
    pub tared: bool,
    /// The whole control interrupt's cost the period before.
    pub isr_last: u32,
    /// The configuration's generation ([`PeriodRunner::config_gen`]).
    pub config_gen: u32,
}

/// The slow figures, every [`STATS_EVERY`] periods.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stats {
    /// Periods run.
    pub periods: u32,
    /// Periods that missed their deadline.
    pub missed: u32,
    /// The control step's cost.
    pub step: StepStats,
    /// The whole control interrupt's cost.
    pub isr: StepStats,
    /// The largest period-start jitter so far, s.
    pub max_jitter_s: f32,
    /// Notes the queue had no room for so far.
    pub notes_dropped: u32,
    /// The serial interrupt's largest cost so far.
    pub serial_max: u32,
    /// Serial interrupts so far.
    pub serial_count: u32,
    /// The motor's estimated winding temperature, C.
    pub winding_c: f32,
    /// Its housing's, C.
    pub housing_c: f32,
    /// The thermal derating of the current limit (1: none).
    pub limit_scale: f32,
    /// What paces the periods.
    pub pacing: hopper_control::runner::Pacing,
    /// The last late period, and the serial interrupts in the periods
    /// around it (the one before it to the one after).
    pub late: Option<(hopper_control::runner::LatePeriod, u32)>,
    /// Bytes the serial line lost so far.
    pub serial_lost: u32,
}

/// Periods between two [`Stats`] (10 ms at 10 kHz).
pub const STATS_EVERY: u32 = 100;

/// Dump records queued per note at most (bounds the link task's work per
/// period; the line is the real limit).
const DUMP_PER_PERIOD: u16 = 4;
