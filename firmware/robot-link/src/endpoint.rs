//! The link task's end ([`Endpoint`]): frames decoded and answered, sets
//! checked and built, requests that act remembered by id.

use super::*;

/// The link task's state (see the [crate documentation](crate)).
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
    pub(crate) spares: heapless::Vec<H, SPARES>,
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
    memo: Memos,
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
pub(crate) enum Memo {
    /// Being carried out: its answer comes from the control period.
    InFlight,
    /// Done.
    Ok,
    /// Refused, with the reason.
    Refused(hopper_protocol::vocab::RefusalCode),
}

/// The requests that act, by id, as answered.
pub(crate) type Memos = heapless::Deque<(u16, Memo), MEMO>;

/// Remembers in `memos` a request that acts and its answer (the oldest
/// forgotten when full).
pub(crate) fn remember(memos: &mut Memos, id: u16, memo: Memo) {
    if let Some(slot) = memos.iter_mut().find(|(i, _)| *i == id) {
        slot.1 = memo;
        return;
    }
    if memos.is_full() {
        let _ = memos.pop_front();
    }
    let _ = memos.push_back((id, memo));
}

impl Memo {
    /// An answer as remembered (`None`: not one a request that acts gets).
    pub(crate) fn of(resp: &Response) -> Option<Self> {
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

/// Whether setting `name` to `value` would switch a protection off
/// ([`params::PROTECTIONS`]); a NaN is not the safe value either.
fn unsafe_value(name: &str, value: f32) -> bool {
    params::PROTECTIONS
        .iter()
        .any(|(p, safe)| p.name == name && value != *safe)
}

/// The answer to a host's hello: this robot's protocol version.
pub(crate) fn send_hello<T: Tx>(tx: &mut T) {
    send(
        tx,
        &RobotMsg::Hello {
            version: PROTOCOL_VERSION,
        },
        false,
    );
}

/// Frames `msg` into `tx` if it has room for it (plus one more frame when
/// `bulk`); whether it went.
pub(crate) fn send<T: Tx>(tx: &mut T, msg: &RobotMsg, bulk: bool) -> bool {
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
    /// changes arrive as the control period's answers, [`Answer::Reply`]).
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
                send_hello(tx);
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
                if crate::LIFT_RANGE_M.contains(lift_m) {
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

    /// Remembers a request that acts and its answer.
    fn remember(&mut self, id: u16, memo: Memo) {
        remember(&mut self.memo, id, memo);
    }

    /// The serial line's losses, as the application counts them (the
    /// board's USART), for [`Request::LinkCounts`].
    pub fn set_serial_counts(&mut self, counts: SerialCounts) {
        self.serial = counts;
    }

    pub(crate) fn link_counts(&self) -> LinkCounts {
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
