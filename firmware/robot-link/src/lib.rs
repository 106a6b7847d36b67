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

pub mod hil;

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

/// What paces the periods, on the wire.
fn pacing(p: hopper_control::runner::Pacing) -> hopper_protocol::vocab::Pacing {
    use hopper_control::runner::Pacing as P;
    match p {
        P::Trigger { .. } => hopper_protocol::vocab::Pacing::Trigger,
        P::NoClock => hopper_protocol::vocab::Pacing::NoClock,
        P::Host => hopper_protocol::vocab::Pacing::Host,
        P::Sustained => hopper_protocol::vocab::Pacing::Sustained,
    }
}

/// How a period was late, on the wire.
fn late_cause(c: hopper_control::runner::LateCause) -> hopper_protocol::vocab::LateCause {
    use hopper_control::runner::LateCause as C;
    match c {
        C::Deadline => hopper_protocol::vocab::LateCause::Deadline,
        C::Start => hopper_protocol::vocab::LateCause::Start,
    }
}

/// The disarm reasons by their wire code ([`ArmState::Disarmed`]).
pub const DISARM_REASONS: [DisarmReason; 6] = [
    DisarmReason::Boot,
    DisarmReason::WatchdogReset,
    DisarmReason::Command,
    DisarmReason::Estop,
    DisarmReason::Fault,
    DisarmReason::LinkLost,
];

/// The control period's end of the link: see the [module
/// documentation](self).
#[derive(Debug, Clone, Default)]
pub struct ControlPort {
    /// The id of an arm request applied, decided at the next period.
    pending_arm: Option<u16>,
    /// An answer decided but not yet queued (no room).
    held: Option<(u16, Response)>,
    /// Periods until a queued restart (0: none).
    restart_in: u32,
    /// The whole interrupt's cost, as the application measured it.
    isr: StepStats,
    /// Its last sample.
    isr_last: u32,
    /// The serial interrupt's largest cost, count and bytes lost so far
    /// (it preempts the control interrupt; the application measures it).
    serial: (u32, u32, u32),
    /// The serial interrupts counted at the last three periods' ends
    /// (period, count), oldest first: what preempted a late period.
    serial_at: [(u32, u32); 3],
    /// The last late period, with the serial interrupts around it.
    late: Option<(hopper_control::runner::LatePeriod, u32)>,
    notes_dropped: u32,
    /// The simulated e-stop, as last asked.
    sim_estop: bool,
    /// A simulated mount change not yet taken by the plant.
    sim_mount: Option<(bool, f32)>,
}

/// Answers the port keeps room for before it takes a command: the held
/// one, a routine's rebuild, the command's own, the slot it frees.
const ANSWER_ROOM: usize = 4;

impl ControlPort {
    /// No command applied yet; the configuration goes to the link task at
    /// the first period.
    pub fn new() -> Self {
        Self::default()
    }

    /// The whole control interrupt's cost this period, in the counter's
    /// units (entry to exit, measured by the application).
    pub fn add_isr_cost(&mut self, cost: u32) {
        self.isr.add(cost);
        self.isr_last = cost;
    }

    /// The whole control interrupt's cost so far.
    pub fn isr_cost(&self) -> &StepStats {
        &self.isr
    }

    /// The serial interrupt's largest cost and how many ran so far, in the
    /// counter's units, and the bytes the line lost so far (an overrun, a
    /// full receive queue), published with the next note.
    pub fn set_serial_cost(&mut self, max: u32, count: u32, lost: u32) {
        self.serial = (max, count, lost);
    }

    /// The simulated e-stop as the host last set it (never on a real
    /// robot: its link refuses the request); the application applies it
    /// to its sensor models.
    pub fn sim_estop(&self) -> bool {
        self.sim_estop
    }

    /// The simulated mount change the host asked for since the last call
    /// (hoisted, toe height to lift to, m); the application moves its
    /// plant.
    pub fn take_sim_mount(&mut self) -> Option<(bool, f32)> {
        self.sim_mount.take()
    }

    /// After [`PeriodRunner::run_period`]: the period into `capture`
    /// (frozen around a fault), a decided arm answered, a routine's
    /// rebuild or a changed configuration handed to the link task, at most
    /// one command applied, and the period's note published.
    #[allow(clippy::too_many_arguments)]
    pub fn after_period<const N: usize, H: HopperSlot>(
        &mut self,
        runner: &mut PeriodRunner<H>,
        p: &Period,
        capture: &mut FaultCapture<N>,
        commands: &mut impl Inbox<Command<H>>,
        answers: &mut impl Outbox<Answer<H>>,
        notes: &mut impl Outbox<Note>,
        stats: &mut impl Outbox<Stats>,
        logs: &mut impl Outbox<LogItem>,
    ) {
        capture.record(&p.out.record, !p.newly_latched.is_empty());
        // A pending arm request was decided in this period. No Armed or
        // Refused event means it changed nothing (already armed, or a
        // disarm applied in between won).
        if let Some(id) = self.pending_arm.take() {
            let resp = match p.arm_event {
                Some(ArmEvent::Refused(r)) => refused(arm_refusal(r)),
                _ if p.armed => Response::Ok,
                _ => refused(Refusal::DisarmRequested),
            };
            self.held = Some((id, resp));
        }
        // (Checked first: `take` copies the whole option.)
        if let Some((id, resp)) = self.held.is_some().then(|| self.held.take()).flatten() {
            let a = Answer::Reply {
                id: Some(id),
                resp,
                set: false,
            };
            if let Err(Answer::Reply {
                id: Some(id), resp, ..
            }) = answers.put(a)
            {
                self.held = Some((id, resp));
            }
        }
        if answers.room() >= ANSWER_ROOM {
            if let Some((changes, then)) = runner.take_rebuild_request() {
                let _ = answers.put(Answer::Rebuild {
                    generation: runner.config_gen(),
                    changes,
                    then,
                });
            }
        }
        if self.held.is_none() && answers.room() >= ANSWER_ROOM {
            if let Some(c) = commands.take() {
                runner.arming_mut().link_frame();
                let set = matches!(c, Command::SetLive { .. } | Command::Install { .. });
                let (reply, spare) = self.apply(c, runner, capture);
                if let Some((id, resp)) = reply {
                    let _ = answers.put(Answer::Reply { id, resp, set });
                }
                if let Some(h) = spare {
                    // Room was kept for it: a slot is never lost.
                    let _ = answers.put(Answer::Spare(h));
                }
            }
        }
        let note = Note {
            record: p.out.record,
            arm_event: p.arm_event,
            arm: runner.arming().state(),
            arm_pending: runner.arming().arm_pending() || self.pending_arm.is_some(),
            calibrating: runner.calibrating(),
            tared: runner.arming().tared(),
            isr_last: self.isr_last,
            config_gen: runner.config_gen(),
        };
        if notes.put(note).is_err() {
            self.notes_dropped = self.notes_dropped.saturating_add(1);
        }
        if let Some(item) = p.log {
            // After the note: the link task sends the state change first.
            if logs.put(item).is_err() {
                self.notes_dropped = self.notes_dropped.saturating_add(1);
            }
        }
        self.note_late(runner);
        if runner.periods().is_multiple_of(STATS_EVERY) {
            let _ = stats.put(self.stats(runner));
        }
    }

    /// The serial interrupts at this period's end; a late period the
    /// runner recorded, once the period after it ended, with the serial
    /// interrupts from the one before it to the one after.
    fn note_late<H: HopperSlot>(&mut self, runner: &PeriodRunner<H>) {
        let this = runner.periods().wrapping_sub(1);
        self.serial_at = [self.serial_at[1], self.serial_at[2], (this, self.serial.1)];
        let Some(l) = runner.last_late() else {
            return;
        };
        let [(before, first), _, (after, last)] = self.serial_at;
        let new = self.late.is_none_or(|(seen, _)| seen != l);
        if new && after == l.period.wrapping_add(1) && before == l.period.wrapping_sub(1) {
            self.late = Some((l, last.wrapping_sub(first)));
        }
    }

    /// A command applied: its answer, and a slot it freed.
    #[allow(clippy::type_complexity)]
    fn apply<const N: usize, H: HopperSlot>(
        &mut self,
        c: Command<H>,
        runner: &mut PeriodRunner<H>,
        capture: &mut FaultCapture<N>,
    ) -> (Option<(Option<u16>, Response)>, Option<H>) {
        let set_refused = |e: SetError| refused(set_refusal(&e));
        if let Command::Install { id, prepared, then } = c {
            let (r, slot) = runner.install(prepared, then);
            return (
                Some((id, r.map_or_else(set_refused, |()| Response::Ok))),
                H::RECYCLED.then_some(slot),
            );
        }
        let reply = match c {
            Command::Alive => None,
            // A save waits for the reset: nothing arms before it.
            Command::Arm { id } if self.restart_in > 0 => Some((id, refused(Refusal::Restarting))),
            Command::Arm { id } => {
                runner.arming_mut().request_arm();
                // Answered when the next period decides.
                self.pending_arm = Some(id);
                None
            }
            Command::Disarm { id } => {
                runner.arming_mut().request_disarm();
                Some((id, Response::Ok))
            }
            Command::ResetFaults { id } => {
                let input = runner.hopper().last_input().copied();
                let resp = match input.map(|i| runner.reset_faults(&i)) {
                    Some(Ok(())) => {
                        capture.rearm();
                        Response::Ok
                    }
                    _ if runner.arming().is_armed() => refused(Refusal::DisarmFirst),
                    None => refused(Refusal::NoMeasurementYet),
                    Some(Err(_)) => refused(Refusal::FaultsRemain),
                };
                Some((id, resp))
            }
            Command::SetLive {
                id,
                base_gen,
                param,
                value,
            } => Some((
                id,
                if base_gen == runner.config_gen() {
                    runner
                        .set_live(param, value)
                        .map_or_else(set_refused, |()| Response::Ok)
                } else {
                    set_refused(SetError::Stale)
                },
            )),
            Command::Install { .. } => None,
            Command::RebuildFailed => {
                runner.rebuild_failed();
                None
            }
            Command::Calibrate {
                id,
                routine,
                seconds,
            } => Some((
                id,
                match runner.start_calibration(routine, seconds) {
                    Ok(()) => Response::Ok,
                    Err(e) => refused(cal_refusal(e)),
                },
            )),
            Command::Query { id, what } => Some((id, Self::query(runner, what))),
            Command::Restart => {
                // 0.2 s: the save's answer is out first.
                self.restart_in = ((0.2 / runner.timing().period_s) as u32).max(1);
                None
            }
            Command::SimulateEstop { id, pressed } => {
                self.sim_estop = pressed;
                Some((id, Response::Ok))
            }
            Command::SimulateMount {
                id,
                hoisted,
                lift_m,
            } => {
                self.sim_mount = Some((hoisted, lift_m));
                Some((id, Response::Ok))
            }
        };
        (reply.map(|(id, r)| (Some(id), r)), None)
    }

    fn query<H: HopperSlot>(runner: &PeriodRunner<H>, what: Query) -> Response {
        match what {
            Query::Boot => {
                let b = runner.arming().boot();
                Response::Boot(hopper_protocol::BootInfo {
                    resets: b.resets.0,
                    brown_out_reset_on: b.brown_out_reset_on,
                    clock_as_configured: b.clock_as_configured,
                    sysclk_hz: b.sysclk_hz,
                })
            }
            Query::Crystal => {
                let b = runner.arming().boot();
                Response::Crystal(hopper_protocol::CrystalInfo {
                    expected_hz: b.hse_expected_hz,
                    measured_hz: b.hse_measured_hz,
                    matches: hopper_control::boot::Crystal::matches(
                        b.hse_measured_hz,
                        b.hse_expected_hz,
                    ),
                })
            }
            Query::Stored => {
                let (boot, boot_error, entries) = runner.calibration_at_boot().wire();
                // The save's state is the link task's: it fills it in.
                Response::Stored(StoredInfo {
                    boot,
                    boot_error,
                    entries,
                    save: 0,
                    saved_count: hopper_control::persist::saved_count() as u8,
                })
            }
            Query::CalibrationReport => {
                Response::Calibration(calibration_info(&runner.calibration()))
            }
            Query::BringupResults => {
                Response::BringupResults(bringup_info(&runner.bringup_results()))
            }
            Query::Weighing => Response::Weighing(weighing_info(&runner.weighing())),
            Query::ThermalBoot => {
                let (winding_c, assumed_hot) = runner.thermal_at_boot();
                Response::ThermalBoot(hopper_protocol::ThermalBootInfo {
                    winding_c,
                    assumed_hot,
                })
            }
        }
    }

    fn stats<H: HopperSlot>(&self, runner: &PeriodRunner<H>) -> Stats {
        let m = runner.hopper().supervisor().thermal();
        Stats {
            periods: runner.periods(),
            missed: runner.missed(),
            step: *runner.step_cost(),
            isr: self.isr,
            max_jitter_s: runner.max_jitter_s(),
            notes_dropped: self.notes_dropped,
            serial_max: self.serial.0,
            serial_count: self.serial.1,
            winding_c: m.winding_c(),
            housing_c: m.housing_c(),
            limit_scale: m.limit_scale(),
            pacing: runner.pacing(),
            late: self.late,
            serial_lost: self.serial.2,
        }
    }

    /// Once a period, after [`after_period`](Self::after_period): whether
    /// the application resets now for a save queued by
    /// [`Command::Restart`]. Never while armed: an armed robot is asked to
    /// disarm and the reset waits a period more.
    pub fn restart_due<H: HopperSlot>(&mut self, runner: &mut PeriodRunner<H>) -> bool {
        if self.restart_in == 0 {
            return false;
        }
        self.restart_in -= 1;
        if self.restart_in > 0 {
            return false;
        }
        if runner.arming().is_armed() {
            runner.arming_mut().request_disarm();
            self.restart_in = 1;
            return false;
        }
        true
    }
}

/// The link task's state (see the [module documentation](self)).
#[derive(Debug, Clone)]
pub struct Endpoint<H = Owned> {
    rx: Decoder,
    /// The id of an arm request sent and not yet answered.
    arm_outstanding: Option<u16>,
    /// The id of a routine's start sent and not yet answered.
    calibrate_outstanding: Option<u16>,
    /// The cycle counter's rate, Hz (0: instructions).
    counter_hz: u32,
    /// Telemetry every this many periods (0: off).
    every: u16,
    since: u16,
    seq: u32,
    telemetry_dropped: u32,
    last_apex_m: Option<f32>,
    /// A dump in progress: the next record and the count.
    dump: Option<(u16, u16)>,
    /// Where the dump's oldest record was when it started
    /// ([`FaultCapture::start`](hopper_control::telemetry::FaultCapture::start)): a
    /// fault that latches during the dump is captured, and the records the
    /// dump reads stay the ones it announced, since it reads four a period
    /// and the capture writes one.
    dump_start: usize,
    /// The link task's work per call, in the counter's units.
    cost: StepStats,
    /// A simulated robot ([`simulated`](Self::simulated)).
    simulated: bool,
    /// The calibration record of the last save request, its length, and
    /// whether the application has taken it.
    save_record: SaveRecord,
    save_len: usize,
    save_taken: bool,
    /// The last save's state (`StoredInfo::save`).
    save_state: u8,
    /// Why the board cannot write its flash now, if it cannot
    /// ([`set_save_refusal`](Self::set_save_refusal)).
    save_refusal: Option<Refusal>,
    /// The control period's configuration and its generation
    /// ([`PeriodRunner::config_gen`]), as its answers confirmed them.
    confirmed: (HopperConfig, u32),
    /// The configurations of the changes queued and not yet answered, in
    /// order: parameters are read, and sets checked and built, on the
    /// last (what the control period's will be).
    pending: heapless::Deque<HopperConfig, PENDING>,
    /// The last slow figures.
    stats: Option<Stats>,
    /// The control interrupt's largest cost since the last
    /// [`Request::Cost`].
    isr_recent_max: u32,
    period_s: f32,
    /// The last period's note (`None` before the first).
    last: Option<Note>,
    /// A command that found the queue full and must not be lost (a
    /// routine's rebuild, a restart): sent first next time.
    stash: heapless::Deque<Command<H>, 3>,
    /// Free controller slots (a bank's) for the next sets.
    spares: heapless::Vec<H, SPARES>,
    /// The period of the last command queued (each carries the frames
    /// received to the link timer).
    carried_at: u32,
    /// A hardware-in-the-loop sample received and not yet taken
    /// ([`take_hil_sample`](Self::take_hil_sample)).
    hil: Option<HilSample>,
    /// The last requests that act, by id, and their answers: a host that
    /// heard no answer sends the same request again, and a repeat is
    /// answered from here, never run again (at most once). Cleared by a
    /// new session's hello (its ids start again).
    memo: heapless::Deque<(u16, Memo), MEMO>,
    /// Repeats answered from [`memo`](Self::memo), and dropped while
    /// their first was in flight; second answers from the control period
    /// to one request ([`LinkCounts`]).
    repeats: (u32, u32, u32),
    /// The serial line's losses, as the application counts them.
    serial: SerialCounts,
}

/// Requests that act remembered by their id ([`Endpoint`]'s `memo`): more
/// than a host retries within one request's time, with the requests in
/// between.
const MEMO: usize = 16;

/// A request that acts, as answered.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Memo {
    /// Being carried out: its answer comes from the control period.
    InFlight,
    /// Done.
    Ok,
    /// Refused, with the reason.
    Refused(hopper_protocol::vocab::RefusalCode),
}

impl Memo {
    /// An answer as remembered (`None`: not one a request that acts gets).
    fn of(resp: &Response) -> Option<Self> {
        match resp {
            Response::Ok => Some(Memo::Ok),
            Response::Refused(why) => Some(Memo::Refused(*why)),
            _ => None,
        }
    }
}

/// The serial line's losses on the board ([`LinkCounts`]): bytes
/// received over one still unread (overrun), without their stop bit
/// (framing), with noise, and dropped with the receive queue full.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SerialCounts {
    /// Overruns.
    pub overrun: u32,
    /// Framing errors.
    pub framing: u32,
    /// Noise.
    pub noise: u32,
    /// Receive queue full.
    pub full: u32,
}

/// A calibration record's bytes (an array too long for a derived `Default`).
#[derive(Debug, Clone)]
struct SaveRecord([u8; hopper_control::persist::MAX_RECORD]);

const SAVE_PENDING: u8 = 1;
const SAVE_SAVED: u8 = 2;
const SAVE_FAILED: u8 = 3;
const SAVE_AT_RESTART: u8 = 4;

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
fn refused(r: Refusal) -> Response {
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

impl<H: HopperSlot> Endpoint<H> {
    /// No session yet, telemetry off; `runner`'s configuration (later
    /// changes arrive as [`Answer::Config`]).
    pub fn new(runner: &PeriodRunner<H>) -> Self {
        Self {
            rx: Decoder::new(),
            arm_outstanding: None,
            calibrate_outstanding: None,
            counter_hz: 0,
            every: 0,
            since: 0,
            seq: 0,
            telemetry_dropped: 0,
            last_apex_m: None,
            dump: None,
            dump_start: 0,
            cost: StepStats::new(),
            simulated: false,
            save_record: SaveRecord([0; hopper_control::persist::MAX_RECORD]),
            save_len: 0,
            save_taken: false,
            save_state: 0,
            save_refusal: None,
            confirmed: (*runner.hopper().config(), runner.config_gen()),
            pending: heapless::Deque::new(),
            stats: None,
            isr_recent_max: 0,
            period_s: runner.timing().period_s,
            last: None,
            stash: heapless::Deque::new(),
            spares: heapless::Vec::new(),
            carried_at: 0,
            hil: None,
            memo: heapless::Deque::new(),
            repeats: (0, 0, 0),
            serial: SerialCounts::default(),
        }
    }

    /// The spare slots of a bank (the control period's runner holds the
    /// running one); those beyond [`SPARES`] are not used.
    pub fn with_spares(mut self, spares: impl IntoIterator<Item = H>) -> Self {
        for h in spares {
            let _ = self.spares.push(h);
        }
        self
    }

    /// The endpoint of a simulated robot (the QEMU image, the simulator's
    /// virtual robot): it takes [`Request::SimulateEstop`] and
    /// [`Request::SimulateMount`], which a real robot refuses, and the
    /// parameters that switch protections off.
    pub fn simulated(runner: &PeriodRunner<H>) -> Self {
        Self {
            simulated: true,
            ..Self::new(runner)
        }
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

    /// Why the board cannot write its flash now (the hardware watchdog
    /// option, a supply below the erase's minimum), or `None`: a save
    /// asked for meanwhile is refused with it.
    pub fn set_save_refusal(&mut self, why: Option<Refusal>) {
        self.save_refusal = why;
    }

    /// How the save went: written, failed, or to be written at the next
    /// boot (`deferred`: the board writes its flash in `init`, and the
    /// control period resets it 0.2 s from now, [`Command::Restart`]).
    pub fn save_done(&mut self, ok: bool, deferred: bool) {
        self.save_state = match (ok, deferred) {
            (true, false) => SAVE_SAVED,
            (true, true) => SAVE_AT_RESTART,
            (false, _) => SAVE_FAILED,
        };
        if ok && deferred {
            // (At most one restart and one routine's rebuild wait here.)
            let _ = self.stash.push_back(Command::Restart);
        }
    }

    /// The hardware-in-the-loop sample received since the last call, if
    /// one was (the HIL image runs a period on it). A host runs in
    /// lockstep: it sends the next sample only after the answer to this
    /// one, so a second sample before this one was taken replaces it, and
    /// the host, missing an answer, stops.
    pub fn take_hil_sample(&mut self) -> Option<HilSample> {
        self.hil.take()
    }

    /// Sends a hardware-in-the-loop period's answer; `false` when the
    /// transmit queue had no room (the host, missing it, stops).
    pub fn send_hil<T: Tx>(&mut self, tx: &mut T, actuate: &HilActuate) -> bool {
        send(tx, &RobotMsg::HilActuate(*actuate), false)
    }

    /// Telemetry records the transmit queue could not take so far.
    pub fn telemetry_dropped(&self) -> u32 {
        self.telemetry_dropped
    }

    /// The link task's work per call so far ([`service`](Self::service)).
    pub fn cost(&self) -> &StepStats {
        &self.cost
    }

    /// The last period's note (`None` before the first).
    pub fn last_note(&self) -> Option<&Note> {
        self.last.as_ref()
    }

    /// [`service`](Self::service) with the link task's ends of the queues
    /// in one value (the board's and the QEMU link image's split halves, or
    /// whole [`Queues`] in line).
    pub fn serve<const N: usize, T: Tx, C: CycleCounter>(
        &mut self,
        queues: &mut impl LinkQueues<H>,
        rx: impl Iterator<Item = u8>,
        capture: &mut impl Shared<FaultCapture<N>>,
        tx: &mut T,
        counter: &mut C,
    ) {
        let (commands, answers, notes, stats, logs) = queues.ends();
        self.service(
            notes, stats, logs, answers, commands, rx, capture, tx, counter,
        );
    }

    /// The link task's work, once a period (after the control period, at a
    /// lower priority): the control period's answers and notes (state
    /// changes, faults, hops, telemetry, dump records queued), then every
    /// byte received since the last call (`rx`), decoded and answered or
    /// turned into a [`Command`]. `capture` is the one the control period
    /// records into (a dump reads it). Its cost, measured with `counter`,
    /// goes into [`cost`](Self::cost).
    #[allow(clippy::too_many_arguments)]
    pub fn service<const N: usize, T: Tx, C: CycleCounter>(
        &mut self,
        notes: &mut impl Inbox<Note>,
        stats: &mut impl Inbox<Stats>,
        logs: &mut impl Inbox<LogItem>,
        answers: &mut impl Inbox<Answer<H>>,
        commands: &mut impl Outbox<Command<H>>,
        rx: impl Iterator<Item = u8>,
        capture: &mut impl Shared<FaultCapture<N>>,
        tx: &mut T,
        counter: &mut C,
    ) {
        let t0 = counter.now();
        self.counter_hz = counter.hz();
        while let Some(c) = self.stash.pop_front() {
            if let Err(c) = commands.put(c) {
                let _ = self.stash.push_front(c);
                break;
            }
        }
        while let Some(a) = answers.take() {
            self.on_answer(a, commands, tx);
        }
        while let Some(s) = stats.take() {
            self.stats = Some(s);
        }
        while let Some(n) = notes.take() {
            self.on_note(&n, capture, tx);
            self.last = Some(n);
        }
        // The period's log items go out after its note's state change.
        while let Some(item) = logs.take() {
            self.on_log(item, tx);
        }
        let mut alive = false;
        let mut asked = false;
        for b in rx {
            if let Some(msg) = self.rx.push::<HostMsg>(b) {
                alive = true;
                asked |= self.on_message(&msg, commands, capture, tx);
            }
        }
        let now = self.last.map_or(0, |n| n.record.step);
        if asked {
            self.carried_at = now;
        } else if alive && now.wrapping_sub(self.carried_at) >= ALIVE_EVERY {
            // Nothing else carries the frames to the link timer (a full
            // queue carries them already).
            if commands.put(Command::Alive).is_ok() {
                self.carried_at = now;
            }
        }
        let t1 = counter.now();
        self.cost
            .add(t1.wrapping_sub(t0).saturating_sub(counter.overhead()));
    }

    fn on_answer<T: Tx>(
        &mut self,
        a: Answer<H>,
        commands: &mut impl Outbox<Command<H>>,
        tx: &mut T,
    ) {
        match a {
            Answer::Reply { id, mut resp, set } => {
                if set {
                    // Changes are applied in the order they were queued.
                    if let Some(cfg) = self.pending.pop_front() {
                        if resp == Response::Ok {
                            self.confirmed = (cfg, self.confirmed.1.wrapping_add(1));
                        }
                    }
                }
                let Some(id) = id else {
                    return;
                };
                if self.arm_outstanding == Some(id) {
                    self.arm_outstanding = None;
                }
                if self.calibrate_outstanding == Some(id) {
                    self.calibrate_outstanding = None;
                }
                if let Response::Stored(s) = &mut resp {
                    s.save = self.save_state;
                }
                if let Some(slot) = self.memo.iter_mut().find(|(i, _)| *i == id) {
                    if slot.1 == Memo::InFlight {
                        slot.1 = Memo::of(&resp).unwrap_or(Memo::InFlight);
                    } else {
                        // The control period carried one request out twice.
                        self.repeats.2 = self.repeats.2.saturating_add(1);
                    }
                }
                send(tx, &RobotMsg::Response { id, resp }, false);
            }
            Answer::Spare(h) => {
                let _ = self.spares.push(h);
            }
            Answer::Rebuild {
                generation,
                changes,
                then,
            } => {
                // On the control period's configuration (no host set is in
                // flight: they are refused while a routine runs).
                let cfg = PeriodRunner::apply_changes(&self.confirmed.0, &changes);
                let prepared = cfg
                    .and_then(|cfg| PeriodRunner::prepare_at(cfg, generation))
                    .ok()
                    .filter(|_| !self.pending.is_full())
                    .and_then(|p| p.into_slot(self.spares.pop()));
                let c = match prepared {
                    Some(prepared) => {
                        let _ = self.pending.push_back(*prepared.config());
                        Command::Install {
                            id: None,
                            prepared,
                            then,
                        }
                    }
                    None => Command::RebuildFailed,
                };
                if !self.stash.is_empty() {
                    // Behind what waits already, in order.
                    let _ = self.stash.push_back(c);
                } else if let Err(c) = commands.put(c) {
                    let _ = self.stash.push_back(c);
                }
            }
        }
    }

    /// The configuration the control period's will be once the changes in
    /// flight are applied.
    fn config(&self) -> &HopperConfig {
        self.pending.back().unwrap_or(&self.confirmed.0)
    }

    /// Its generation.
    fn generation(&self) -> u32 {
        self.confirmed.1.wrapping_add(self.pending.len() as u32)
    }

    /// Whether the last note says armed.
    fn armed(&self) -> bool {
        matches!(self.last.map(|n| n.arm), Some(RunnerArmState::Armed))
    }

    /// A decoded message: answers it, or queues the command that will
    /// (whether one was queued).
    fn on_message<const N: usize, T: Tx>(
        &mut self,
        msg: &HostMsg,
        commands: &mut impl Outbox<Command<H>>,
        capture: &mut impl Shared<FaultCapture<N>>,
        tx: &mut T,
    ) -> bool {
        let (id, req) = match msg {
            HostMsg::Hello { .. } => {
                // A new session: its ids start again.
                self.memo.clear();
                send(
                    tx,
                    &RobotMsg::Hello {
                        version: PROTOCOL_VERSION,
                    },
                    false,
                );
                return false;
            }
            HostMsg::Heartbeat => return false,
            HostMsg::HilSample(sample) => {
                self.hil = Some(*sample);
                return false;
            }
            HostMsg::Request { id, req } => (*id, req),
        };
        let acting = req.acts();
        if acting {
            if let Some(&(_, memo)) = self.memo.iter().find(|(i, _)| *i == id) {
                let resp = match memo {
                    Memo::InFlight => {
                        self.repeats.1 = self.repeats.1.saturating_add(1);
                        return false;
                    }
                    Memo::Ok => Response::Ok,
                    Memo::Refused(why) => Response::Refused(why),
                };
                self.repeats.0 = self.repeats.0.saturating_add(1);
                send(tx, &RobotMsg::Response { id, resp }, false);
                return false;
            }
        }
        let note = self.last;
        let calibrating = note.is_some_and(|n| n.calibrating);
        let command = |c: Command<H>| -> Result<Command<H>, Response> { Ok(c) };
        let mut predicted = None;
        let out: Result<Command<H>, Response> = match req {
            Request::Status => Err(Response::Status(self.status())),
            // The board resets shortly to write a save: nothing starts.
            Request::Arm | Request::Calibrate { .. } if self.save_state == SAVE_AT_RESTART => {
                Err(refused(Refusal::Restarting))
            }
            // A save queued but not yet taken becomes a reset on the
            // board: nothing starts before it is done.
            Request::Arm | Request::Calibrate { .. } if self.save_state == SAVE_PENDING => {
                Err(refused(Refusal::Saving))
            }
            Request::Arm => command(Command::Arm { id }),
            Request::Disarm => command(Command::Disarm { id }),
            Request::ResetFaults => command(Command::ResetFaults { id }),
            Request::ParamCount => Err(Response::ParamCount(params::TABLE.len() as u16)),
            Request::ParamInfo { index } => Err(match params::TABLE.get(usize::from(*index)) {
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
                        value: params::get(self.config(), p.name).unwrap_or(f32::NAN),
                        live: PeriodRunner::settable_while_armed(p),
                    })
                }
                None => refused(Refusal::NoSuchIndex),
            }),
            Request::ParamGet { name } => Err(match params::get(self.config(), name) {
                Ok(v) => Response::Value(v),
                Err(_) => refused(Refusal::UnknownParameter),
            }),
            Request::ParamSet { name, value } if !self.simulated && unsafe_value(name, *value) => {
                Err(refused(Refusal::ProtectionLocked))
            }
            Request::ParamSet { name, value } => {
                match self.plan_set(id, name, *value, calibrating) {
                    Ok((c, cfg)) => {
                        predicted = Some(cfg);
                        Ok(c)
                    }
                    Err(r) => Err(r),
                }
            }
            Request::Telemetry { every } => {
                self.every = *every;
                self.since = 0;
                Err(Response::Ok)
            }
            Request::Timing => {
                let st = self.stats;
                let (periods, missed, step) =
                    st.map_or((0, 0, StepStats::new()), |n| (n.periods, n.missed, n.step));
                Err(Response::Timing(TimingStats {
                    period_s: self.period_s,
                    periods,
                    missed,
                    step_mean: step.mean(),
                    step_max: step.max,
                    link_mean: self.cost.mean(),
                    link_max: self.cost.max,
                }))
            }
            Request::Cost => {
                let st = self.stats;
                let isr = st.map_or(StepStats::new(), |n| n.isr);
                let recent = core::mem::take(&mut self.isr_recent_max);
                Err(Response::Cost(CostStats {
                    counter_hz: self.counter_hz,
                    isr_mean: isr.mean(),
                    isr_max: isr.max,
                    isr_max_recent: recent,
                    link_mean: self.cost.mean(),
                    link_max: self.cost.max,
                    serial_max: st.map_or(0, |n| n.serial_max),
                    serial_count: st.map_or(0, |n| n.serial_count),
                    max_jitter_s: st.map_or(0.0, |n| n.max_jitter_s),
                    notes_dropped: st.map_or(0, |n| n.notes_dropped),
                    pacing: st
                        .map_or(hopper_protocol::vocab::Pacing::NoClock, |n| {
                            pacing(n.pacing)
                        })
                        .code(),
                    late_period: st
                        .and_then(|n| n.late)
                        .map_or(hopper_protocol::NO_LATE_PERIOD, |(l, _)| l.period),
                    late_cause: st
                        .and_then(|n| n.late)
                        .map_or(0, |(l, _)| late_cause(l.cause).code()),
                    late_jitter_s: st.and_then(|n| n.late).map_or(0.0, |(l, _)| l.jitter_s),
                    late_serial: st.and_then(|n| n.late).map_or(0, |(_, k)| k),
                    serial_lost: st.map_or(0, |n| n.serial_lost),
                }))
            }
            Request::Thermal => {
                let c = &self.confirmed.0.supervisor.thermal;
                let st = self.stats;
                Err(Response::Thermal(ThermalStatus {
                    winding_c: st.map_or(f32::NAN, |n| n.winding_c),
                    housing_c: st.map_or(f32::NAN, |n| n.housing_c),
                    limit_scale: st.map_or(1.0, |n| n.limit_scale),
                    derate_c: c.derate_winding_c,
                    trip_c: c.trip_winding_c,
                    protect: c.protect,
                }))
            }
            Request::Boot => command(Command::Query {
                id,
                what: Query::Boot,
            }),
            Request::Calibrate { routine, seconds } => {
                match hopper_control::bringup::Routine::from_code(*routine) {
                    None => Err(refused(Refusal::UnknownRoutine)),
                    Some(routine) => command(Command::Calibrate {
                        id,
                        routine,
                        seconds: *seconds,
                    }),
                }
            }
            Request::CalibrationReport => command(Command::Query {
                id,
                what: Query::CalibrationReport,
            }),
            Request::BringupResults => command(Command::Query {
                id,
                what: Query::BringupResults,
            }),
            Request::SimulateMount { hoisted, lift_m } if self.simulated => {
                if (0.0..=0.5).contains(lift_m) {
                    command(Command::SimulateMount {
                        id,
                        hoisted: *hoisted,
                        lift_m: *lift_m,
                    })
                } else {
                    Err(refused(Refusal::LiftOutOfRange))
                }
            }
            Request::SimulateMount { .. } => Err(refused(Refusal::NotSimulated)),
            Request::Save => Err(self.save(note)),
            Request::Weighing => command(Command::Query {
                id,
                what: Query::Weighing,
            }),
            Request::Crystal => command(Command::Query {
                id,
                what: Query::Crystal,
            }),
            Request::Stored => command(Command::Query {
                id,
                what: Query::Stored,
            }),
            Request::ThermalBoot => command(Command::Query {
                id,
                what: Query::ThermalBoot,
            }),
            Request::SimulateEstop { pressed } if self.simulated => {
                command(Command::SimulateEstop {
                    id,
                    pressed: *pressed,
                })
            }
            Request::SimulateEstop { .. } => Err(refused(Refusal::NotSimulated)),
            Request::Dump => Err(self.start_dump(capture)),
            Request::ParamMeta { name } => Err(param_meta(name.as_str())),
            Request::ParamChoice { name, value } => Err(param_choice(name.as_str(), *value)),
            Request::LinkCounts => Err(Response::LinkCounts(self.link_counts())),
        };
        if acting {
            let memo = match &out {
                Ok(_) => Some(Memo::InFlight),
                Err(resp) => Memo::of(resp),
            };
            if let Some(m) = memo {
                self.remember(id, m);
            }
        }
        match out {
            Ok(c) => {
                let arm = matches!(c, Command::Arm { .. });
                let calibrate = matches!(c, Command::Calibrate { .. });
                match commands.put(c) {
                    Ok(()) => {
                        if arm {
                            self.arm_outstanding = Some(id);
                        }
                        if calibrate {
                            self.calibrate_outstanding = Some(id);
                        }
                        if let Some(cfg) = predicted {
                            // The next set builds on this one (its install
                            // adds one to the generation).
                            let _ = self.pending.push_back(cfg);
                        }
                        true
                    }
                    Err(c) => {
                        // A slot it held is free again.
                        if let Command::Install { prepared, .. } = c {
                            if H::RECYCLED {
                                let _ = self.spares.push(prepared.into_slot_handle());
                            }
                        }
                        let resp = refused(Refusal::Busy);
                        if acting {
                            self.remember(id, Memo::of(&resp).unwrap_or(Memo::InFlight));
                        }
                        send(tx, &RobotMsg::Response { id, resp }, false);
                        false
                    }
                }
            }
            Err(resp) => {
                send(tx, &RobotMsg::Response { id, resp }, false);
                false
            }
        }
    }

    /// A parameter set, checked and its controller built here: the command
    /// that applies it, or the refusal.
    fn plan_set(
        &mut self,
        id: u16,
        name: &str,
        value: f32,
        calibrating: bool,
    ) -> Result<(Command<H>, HopperConfig), Response> {
        let set_refused = |e: SetError| refused(set_refusal(&e));
        if params::find(name).is_some() && calibrating {
            return Err(set_refused(SetError::Calibrating));
        }
        let (param, cfg) =
            PeriodRunner::plan_set(self.config(), name, value).map_err(set_refused)?;
        if self.pending.is_full() {
            return Err(refused(Refusal::Busy));
        }
        if self.armed() {
            if !PeriodRunner::settable_while_armed(param) {
                return Err(set_refused(SetError::WhileArmed(param.name)));
            }
            let base_gen = self.generation();
            return Ok((
                Command::SetLive {
                    id,
                    base_gen,
                    param,
                    value,
                },
                cfg,
            ));
        }
        // The controller's constants and every cross-field rule, here: the
        // control period only copies it in.
        let prepared = PeriodRunner::prepare_at(cfg, self.generation())
            .map_err(set_refused)?
            .into_slot(self.spares.pop())
            .ok_or_else(|| refused(Refusal::Busy))?;
        Ok((
            Command::Install {
                id: Some(id),
                prepared,
                then: Then::Param(param),
            },
            cfg,
        ))
    }

    fn save(&mut self, note: Option<Note>) -> Response {
        let Some(n) = note else {
            return refused(Refusal::Busy);
        };
        if self.armed() {
            return refused(Refusal::DisarmFirst);
        }
        // An arm decided at a later period would arm a robot that the save
        // then resets.
        if self.arm_outstanding.is_some() || n.arm_pending {
            return refused(Refusal::Arming);
        }
        if n.calibrating || self.calibrate_outstanding.is_some() {
            return refused(Refusal::Calibrating);
        }
        // The record is the control period's configuration, as this task
        // knows it: only when no change is in flight and the last period
        // ran on it (a tare installed but not yet answered would be
        // saved without its offsets).
        if !self.pending.is_empty() || self.confirmed.1 != n.config_gen {
            return refused(Refusal::Busy);
        }
        // The placeholders are not a calibration: a tare (or a loaded
        // record) first, else the saved record would stand for one.
        if !n.tared {
            return refused(Refusal::NotCalibrated);
        }
        if self.save_state == SAVE_PENDING {
            return refused(Refusal::Busy);
        }
        if let Some(why) = self.save_refusal {
            return refused(why);
        }
        self.save_len = hopper_control::persist::encode(&self.confirmed.0, &mut self.save_record.0);
        self.save_taken = false;
        self.save_state = SAVE_PENDING;
        Response::Ok
    }

    fn start_dump<const N: usize>(
        &mut self,
        capture: &mut impl Shared<FaultCapture<N>>,
    ) -> Response {
        let (len, start, frozen, fault_step) = capture.with(|c| {
            c.hold(true);
            (c.len(), c.start(), c.frozen(), c.fault_step().unwrap_or(0))
        });
        let records = u16::try_from(len).unwrap_or(u16::MAX);
        self.dump = Some((0, records));
        self.dump_start = start;
        Response::Dump(DumpInfo {
            records,
            frozen,
            fault_step,
        })
    }

    /// A period's log item: its message, after the period's note.
    fn on_log<T: Tx>(&mut self, item: LogItem, tx: &mut T) {
        match Some(item) {
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
                let hop = wire_hop(&h);
                send(tx, &RobotMsg::Hop(hop), false);
            }
            None => {}
        }
    }

    /// A period's note: the messages it produced.
    fn on_note<const N: usize, T: Tx>(
        &mut self,
        n: &Note,
        capture: &mut impl Shared<FaultCapture<N>>,
        tx: &mut T,
    ) {
        self.isr_recent_max = self.isr_recent_max.max(n.isr_last);
        if let Some(ev) = n.arm_event {
            let state = match ev {
                ArmEvent::Armed => Some(ArmState::Armed),
                ArmEvent::Disarmed(r) => Some(arm_state(RunnerArmState::Disarmed(r))),
                ArmEvent::Refused(_) => None,
            };
            if let Some(s) = state {
                send(tx, &RobotMsg::State(s), false);
            }
        }
        if self.every > 0 {
            self.since = self.since.saturating_add(1);
            if self.since >= self.every {
                self.since = 0;
                let t = RobotMsg::Telemetry(wire_record(self.seq, &n.record));
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
            let start = self.dump_start;
            while next < end {
                // One record copied out under the capture's lock at a time.
                let Some(r) = capture.with(|c| c.get_from(start, usize::from(next)).copied())
                else {
                    break;
                };
                if !send(
                    tx,
                    &RobotMsg::Captured(wire_record(u32::from(next), &r)),
                    true,
                ) {
                    break;
                }
                next += 1;
            }
            let more =
                next < total && capture.with(|c| c.get_from(start, usize::from(next)).is_some());
            self.dump = more.then_some((next, total));
            if self.dump.is_none() {
                capture.with(|c| c.hold(false));
            }
        }
    }

    /// Remembers a request that acts and its answer (the oldest
    /// forgotten when full).
    fn remember(&mut self, id: u16, memo: Memo) {
        if let Some(slot) = self.memo.iter_mut().find(|(i, _)| *i == id) {
            slot.1 = memo;
            return;
        }
        if self.memo.is_full() {
            let _ = self.memo.pop_front();
        }
        let _ = self.memo.push_back((id, memo));
    }

    /// The serial line's losses, as the application counts them (the
    /// board's USART), for [`Request::LinkCounts`].
    pub fn set_serial_counts(&mut self, counts: SerialCounts) {
        self.serial = counts;
    }

    fn link_counts(&self) -> LinkCounts {
        let link = self.rx.stats();
        LinkCounts {
            frames_ok: link.ok,
            too_long: link.too_long,
            bad_cobs: link.bad_cobs,
            bad_crc: link.bad_crc,
            unknown_message: link.bad_message,
            serial_overrun: self.serial.overrun,
            serial_framing: self.serial.framing,
            serial_noise: self.serial.noise,
            serial_full: self.serial.full,
            repeats_answered: self.repeats.0,
            repeats_in_flight: self.repeats.1,
            applied_twice: self.repeats.2,
            telemetry_dropped: self.telemetry_dropped,
        }
    }

    fn status(&self) -> Status {
        let link = self.rx.stats();
        let n = self.last;
        Status {
            arm: arm_state(n.map_or(RunnerArmState::Disarmed(DisarmReason::Boot), |n| n.arm)),
            faults: n.map_or(0, |n| n.record.faults),
            periods: n.map_or(0, |n| n.record.step),
            frames_ok: link.ok,
            frames_bad: link.bad(),
            telemetry_dropped: self.telemetry_dropped,
            last_apex_m: self.last_apex_m.unwrap_or(f32::NAN),
        }
    }
}

/// A routine's report on the wire (codes for the routine and its state).
fn calibration_info(
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
fn bringup_info(r: &hopper_control::bringup::BringupReport) -> hopper_protocol::BringupResults {
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
fn weighing_info(r: &hopper_control::bringup::WeighingReport) -> hopper_protocol::WeighingInfo {
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

#[cfg(test)]
mod tests {
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
            let runner =
                PeriodRunner::new(cfg, Timing::default()).unwrap_or_else(|e| panic!("{e:?}"));
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
        assert_eq!(n, Some(7 + 13 * 8 + 2));
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
}
