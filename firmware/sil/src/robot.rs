//! The virtual robot: the firmware's period runner and link
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
//! from. The hoist clamps the body only ([`Plant::clamp_body`]): the nut
//! moves under the motor and the spring, so the bring-up routines can
//! drive it. The host moves the robot with `Request::SimulateMount`: the
//! hoist lifts the body at [`LIFT_SPEED_MPS`] to a toe height, or lets go.

use crate::sim_io::SimHal;
use hopper_control::hal::RawSample;
use hopper_control::runner::{CycleCounter, HopperSlot, Owned, Period, PeriodRunner};
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};
use hopper_plant::{Event, Plant, PlantError};
use hopper_robot_link::{ControlLoop, Endpoint, PortQueues, Queues, Tx};

/// How fast the hoist lifts or lowers the body, m/s (2 um a period at 10
/// kHz: the height encoder sees a motion, not a jump).
pub const LIFT_SPEED_MPS: f64 = 0.1;

/// The firmware on the simulated hopper, behind a link; its controller
/// held by value, or in a static bank's slot (`&'static mut Hopper`, the
/// QEMU link image, as the board).
pub struct VirtualRobot<H = Owned> {
    /// The plant.
    pub plant: Plant,
    /// The sensor, DAC and amplifier models.
    pub hal: SimHal,
    /// The firmware's control loop (the period runner and the link's end
    /// in the control period).
    pub firmware: ControlLoop<H>,
    /// Held by the hoist (the body clamped, the nut free) until the first
    /// armed period.
    pub held: bool,
    /// The body height the hoist is moving the body to, m.
    lift_to_m: Option<f64>,
    dt_s: f64,
}

impl<H: HopperSlot> VirtualRobot<H> {
    /// A robot of `runner` (built disarmed) on `plant` and `hal`, stepped
    /// every `dt_s`.
    pub fn new(plant: Plant, hal: SimHal, runner: PeriodRunner<H>, dt_s: f64) -> Self {
        Self {
            plant,
            hal,
            firmware: ControlLoop::new(runner),
            held: false,
            lift_to_m: None,
            dt_s,
        }
    }

    /// Holds the body at rest where the plant starts (a hoist) until armed.
    pub fn hold(mut self) -> Self {
        self.plant.clamp_body();
        self.held = true;
        self
    }

    /// Hoists the body (clamps it where it is) and lifts it until the toe
    /// is `toe_m` above the ground, or lets go (`None`).
    pub fn mount(&mut self, toe_m: Option<f64>) {
        match toe_m {
            Some(h) => {
                self.plant.clamp_body();
                self.held = true;
                self.lift_to_m = Some(self.plant.params().leg_length_m + h);
            }
            None => self.release(),
        }
    }

    fn release(&mut self) {
        self.plant.release_body();
        self.held = false;
        self.lift_to_m = None;
    }

    /// The world before a control period: the simulated e-stop and a
    /// mount change the host asked for applied, then the sensors sampled
    /// (as the board's ADC and timers have the sample when the control
    /// interrupt enters). The sensor models' work is the world's, not the
    /// firmware's: an image that paces its periods with a timer runs this
    /// with the timer stopped, as it does [`advance`](Self::advance).
    pub fn sample(&mut self) -> Option<RawSample> {
        self.hal.faults.estop = self.firmware.port.sim_estop();
        if let Some((hoisted, lift_m)) = self.firmware.port.take_sim_mount() {
            self.mount(hoisted.then_some(f64::from(lift_m)));
        }
        self.hal.take_sample(&self.plant)
    }

    /// One control period on `sample` ([`sample`](Self::sample))
    /// ([`ControlLoop::period`]: the period's record into `capture`, frozen
    /// around a fault, its note published, at most one command applied),
    /// timed with `counter` as the board times its whole control interrupt.
    /// The caller runs the link task ([`Endpoint::serve`]) after it, at a
    /// lower priority or in line ([`control`](Self::control)), and reports
    /// the period's lateness with `runner.end_period`.
    pub fn control_period<C: CycleCounter>(
        &mut self,
        sample: Option<RawSample>,
        capture: &mut FaultCapture<CAPTURE_LEN>,
        queues: &mut impl PortQueues<H>,
        counter: &mut C,
    ) -> Period {
        let mut io = self.hal.with_sample(sample);
        let t0 = counter.now();
        let p = self
            .firmware
            .period(&mut io, counter, &mut &mut *capture, queues);
        let t1 = counter.now();
        self.firmware
            .port
            .add_isr_cost(t1.wrapping_sub(t0).saturating_sub(counter.overhead()));
        if p.armed && self.held {
            // Armed: the hoist lets go (the laws start from the release).
            self.release();
        }
        p
    }

    /// [`control_period`](Self::control_period), then the link task
    /// `link` in line (`hopper-sim serve`, the tests): the period's
    /// messages into `tx`, and `rx` (the bytes that arrived since the last
    /// period) decoded and answered. The caller owns the link task (an
    /// image that runs it as a task of its own keeps it there), the
    /// capture and the queues (32 KiB and 12 KiB).
    pub fn control<C: CycleCounter>(
        &mut self,
        link: &mut Endpoint<H>,
        rx: impl Iterator<Item = u8>,
        tx: &mut impl Tx,
        capture: &mut FaultCapture<CAPTURE_LEN>,
        queues: &mut Queues<H>,
        counter: &mut C,
    ) -> Period {
        let sample = self.sample();
        let p = self.control_period(sample, capture, queues, counter);
        link.serve(queues, rx, &mut &mut *capture, tx, counter);
        p
    }

    /// The plant from this period to the next, under the amplifier's
    /// current (the hoist's move first).
    pub fn advance(&mut self, on_event: &mut impl FnMut(Event)) -> Result<(), PlantError> {
        let current_a = self.hal.mean_current_a(self.dt_s);
        if let Some(z) = self.lift_to_m {
            let step = LIFT_SPEED_MPS * self.dt_s;
            let dz = (z - self.plant.state().z_m).clamp(-step, step);
            self.plant.move_clamped_body(dz);
            if dz.abs() < step {
                self.lift_to_m = None;
            }
        }
        self.plant.advance(self.dt_s, current_a, on_event)
    }
}

/// A robot whose firmware is configured for the nominal machine while the
/// machine differs: what the bring-up routines must find.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Miscalibration {
    /// The load cell reads this much beyond the true spring force, N.
    pub loadcell_bias_n: f64,
    /// The potentiometer reads this much beyond the true leg compression, m.
    pub pot_bias_m: f64,
    /// The nut boots this far below its upper stop, m (the incremental
    /// motor encoder takes it for 0).
    pub nut_start_m: f64,
    /// The real spring's rate is off the configured one by this fraction.
    pub spring_rate_error: f64,
    /// The firmware takes the boot height for this much more than it is, m.
    pub height_zero_error_m: f64,
    /// The load cell's gain is off by this fraction (it reads `F (1 + e)`).
    pub loadcell_gain_error: f64,
}

impl Miscalibration {
    /// A robot as configured.
    pub const NONE: Miscalibration = Miscalibration {
        loadcell_bias_n: 0.0,
        pot_bias_m: 0.0,
        nut_start_m: 0.0,
        spring_rate_error: 0.0,
        height_zero_error_m: 0.0,
        loadcell_gain_error: 0.0,
    };

    /// The CI's link sessions' robot (`hopper-sim serve` and the QEMU link
    /// image): 12 N of load-cell offset, 0.5 mm of potentiometer offset,
    /// the nut 1 mm below its stop, a spring 15% stiffer than configured,
    /// the height zero 30 mm off, the load cell reading 5% low. Each stays
    /// within what the supervisor accepts at boot (its 30 N spring
    /// cross-check).
    pub const SESSION: Miscalibration = Miscalibration {
        loadcell_bias_n: 12.0,
        pot_bias_m: 5.0e-4,
        nut_start_m: 1.0e-3,
        spring_rate_error: 0.15,
        height_zero_error_m: 0.03,
        loadcell_gain_error: -0.05,
    };

    /// The start height the firmware believes for a real `start_apex_m`, m
    /// (what its configuration is built for).
    pub fn believed_start_apex_m(&self, start_apex_m: f64) -> f64 {
        start_apex_m + self.height_zero_error_m
    }

    /// The sensor models with the offsets.
    pub fn sensors(&self, s: crate::sim_io::SensorConfig) -> crate::sim_io::SensorConfig {
        crate::sim_io::SensorConfig {
            loadcell_bias_n: self.loadcell_bias_n,
            pot_bias_m: self.pot_bias_m,
            loadcell_gain_error: self.loadcell_gain_error,
            ..s
        }
    }

    /// The real machine: `nominal` with the spring off, at rest in flight
    /// `start_apex_m` up with the nut where it boots.
    pub fn plant(
        &self,
        nominal: hopper_plant::Params,
        start_apex_m: f64,
    ) -> Result<Plant, hopper_plant::ParamError> {
        let mut real = nominal;
        real.spring_stiffness_n_per_m *= 1.0 + self.spring_rate_error;
        Plant::with_state(
            real,
            hopper_plant::Mode::Flight,
            hopper_plant::State {
                z_m: real.leg_length_m + start_apex_m,
                zd_mps: 0.0,
                p_m: self.nut_start_m,
                pd_mps: 0.0,
            },
        )
    }

    /// The sensor models `hal` (built from the firmware's calibration) with
    /// the height encoder's true origin: the plant's start.
    pub fn hal(&self, hal: SimHal, plant: &Plant) -> SimHal {
        hal.with_height_origin(plant.state().z_m)
    }
}
