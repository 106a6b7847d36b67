//! The virtual robot (issue 17): the firmware's period runner and link
//! endpoint on the plant and sensor models, behind a byte link. The QEMU
//! link image and `hopper-sim serve` both run this one type; only what
//! carries the bytes (QEMU's USART, a TCP socket) and what paces the
//! periods (SysTick, the host's clock) differ.
//!
//! Like the board it boots disarmed and tethered (arming needs a live
//! link); only the host arms it. It boots standing on the ground, or held
//! at rest above it ([`VirtualRobot::held`]: a simulated hoist, as hoppers
//! are started by hand or from a support) and released when armed: the
//! laws hop from a release; from standing they have no touchdown to start
//! from.

use crate::mock::SimHal;
use crate::{Event, Plant, PlantError};
use hopper_control::link::{Endpoint, Tx};
use hopper_control::runner::{CycleCounter, Period, PeriodRunner};
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};

/// The firmware on the simulated hopper, behind a link.
pub struct VirtualRobot {
    /// The plant.
    pub plant: Plant,
    /// The sensor, DAC and amplifier models.
    pub hal: SimHal,
    /// The firmware's period runner.
    pub runner: PeriodRunner,
    /// The link's robot end.
    pub link: Endpoint,
    /// The capture, frozen around a fault.
    pub capture: FaultCapture<CAPTURE_LEN>,
    /// Held at rest where it started until the first armed period (the
    /// plant does not move while held).
    pub held: bool,
    dt_s: f64,
}

impl VirtualRobot {
    /// A robot of `runner` (built disarmed) on `plant` and `hal`, stepped
    /// every `dt_s`.
    pub fn new(plant: Plant, hal: SimHal, runner: PeriodRunner, dt_s: f64) -> Self {
        Self {
            plant,
            hal,
            runner,
            link: Endpoint::simulated(),
            capture: FaultCapture::new(),
            held: false,
            dt_s,
        }
    }

    /// Holds the body at rest where the plant starts until armed.
    pub fn hold(mut self) -> Self {
        self.held = true;
        self
    }

    /// One control period on the sensors' present state, then the link's
    /// work: the period's messages into `tx`, and `rx` (the bytes that
    /// arrived since the last period) decoded and answered. The caller
    /// reports the period's lateness with `runner.end_period`.
    pub fn control<C: CycleCounter>(
        &mut self,
        rx: impl Iterator<Item = u8>,
        tx: &mut impl Tx,
        counter: &mut C,
    ) -> Period {
        self.hal.faults.estop = self.link.sim_estop();
        let p = {
            let mut io = self.hal.io(&self.plant);
            self.runner.run_period(&mut io, counter)
        };
        self.capture
            .record(&p.out.record, !p.newly_latched.is_empty());
        self.link
            .service(&mut self.runner, &p, rx, &mut self.capture, tx, counter);
        if p.armed {
            self.held = false;
        }
        p
    }

    /// The plant from this period to the next, under the amplifier's
    /// current (nothing moves while held).
    pub fn advance(&mut self, on_event: &mut impl FnMut(Event)) -> Result<(), PlantError> {
        let current_a = self.hal.mean_current_a(self.dt_s);
        if self.held {
            return Ok(());
        }
        self.plant.advance(self.dt_s, current_a, on_event)
    }
}
