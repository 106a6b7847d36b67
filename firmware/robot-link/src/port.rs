//! The control period's end of the link ([`ControlPort`]): at most one
//! command applied a period, the period's note published.

use super::*;

/// The disarm reasons by their wire code ([`ArmState::Disarmed`]).
pub const DISARM_REASONS: [DisarmReason; 6] = [
    DisarmReason::Boot,
    DisarmReason::WatchdogReset,
    DisarmReason::Command,
    DisarmReason::Estop,
    DisarmReason::Fault,
    DisarmReason::LinkLost,
];

/// The control period's end of the link: see the [crate
/// documentation](crate).
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
