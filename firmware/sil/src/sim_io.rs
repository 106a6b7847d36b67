//! The simulated hardware: the plant seen through the hopper's sensors and driven
//! through its DAC and amplifier, behind the firmware's own
//! [`HopperIo`] trait.
//!
//! [`SimHal`] holds the sensor, DAC and amplifier models; [`SimHal::io`]
//! lends it, with the plant, as a [`HopperIo`] for one control period, and
//! [`SimHal::mean_current_a`] gives the current the plant then sees over
//! the period (the amplifier's first-order lag, the enable, the DAC
//! resolution). The sensor models are the inverse of the firmware's
//! [`Calibration`], so a perfect sensor converts back to the plant's value
//! within one quantum.
//!
//! `no_std`: this also runs inside the QEMU image.

use hopper_control::calibration::Calibration;
use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::{HopperConfig, Strategy};
use hopper_control::model::ModelParams;
use hopper_plant::params::Params;
use hopper_plant::plant::{Mode, Plant};
use hopper_plant::sensors::{AdcChannel, Amplifier, Encoder, LagFactor, Noise};

/// The plant parameters as the control crate's model (`f32`, what the
/// controller believes when it knows the plant exactly).
pub fn model_params(p: &Params) -> ModelParams {
    ModelParams {
        body_mass_kg: p.body_mass_kg as f32,
        unsprung_mass_kg: p.unsprung_mass_kg as f32,
        nut_mass_kg: p.nut_mass_kg as f32,
        rotor_inertia_kg_m2: p.rotor_inertia_kg_m2 as f32,
        screw_lead_m: p.screw_lead_m as f32,
        spring_stiffness_n_per_m: p.spring_stiffness_n_per_m as f32,
        leg_length_m: p.leg_length_m as f32,
        preload_m: p.spring_preload_m as f32,
        stroke_m: p.stroke_m as f32,
        efficiency: p.efficiency as f32,
        gravity_mps2: p.gravity_mps2 as f32,
        torque_limit_nm: p.max_torque_nm() as f32,
        torque_constant_nm_per_a: p.torque_constant_nm_per_a as f32,
        current_limit_a: p.current_limit_a as f32,
    }
}

/// The firmware configuration for a simulated run: the defaults for the
/// model the controller believes (`believed`), the given strategy and apex
/// target, and the height encoder's origin at the release height
/// `plant.leg_length_m + start_apex_m` (the height encoder is incremental:
/// on the real robot, the firmware is told the height of the stand it is
/// released from). The host runner and the QEMU image both build their
/// controller through this, so they run the same configuration.
pub fn firmware_config(
    plant: &Params,
    believed: &Params,
    strategy: Strategy,
    target_apex_m: f64,
    start_apex_m: f64,
) -> HopperConfig {
    let mut cfg = HopperConfig::for_model(model_params(believed));
    // The supervisor's spring check compares two sensors (load cell against
    // potentiometer and encoder) through the spring rate and preload: on a
    // robot those are calibrated on the bench, not taken from the control
    // model, so a wrong control model (`--model-params`) must not trip it.
    cfg.supervisor.spring_rate_n_per_m = plant.spring_stiffness_n_per_m as f32;
    cfg.supervisor.spring_preload_m = plant.spring_preload_m as f32;
    cfg.strategy = strategy;
    cfg.target_apex_m = target_apex_m as f32;
    cfg.calibration.height_at_origin_m = (plant.leg_length_m + start_apex_m) as f32;
    cfg
}

/// Sensor noise and amplifier settings of the simulated hardware.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorConfig {
    /// Draw Gaussian noise (`false`: quantisation only).
    pub noise: bool,
    /// Seed of the noise generator (same seed, same run).
    pub seed: u64,
    /// Load-cell noise, N (1 sigma). Default 2.0 (4 codes at the default 0.5 N/code).
    pub loadcell_sigma_n: f64,
    /// Potentiometer noise, m (1 sigma). Default 1e-4 (about 3.4 codes).
    pub pot_sigma_m: f64,
    /// Amplifier current-loop time constant, s. Default 1.5e-4 (about 1 kHz bandwidth).
    pub amp_tau_s: f64,
    /// What the load cell reads beyond the true spring force, N: its offset
    /// against the firmware's calibration (a mis-calibrated sensor for the
    /// bring-up routines to find). Default 0.
    pub loadcell_bias_n: f64,
    /// What the potentiometer reads beyond the true leg compression, m.
    /// Default 0.
    pub pot_bias_m: f64,
    /// The load cell's gain error against the firmware's calibration: it
    /// reads `F (1 + e) + bias` for a spring force `F` (a load cell whose
    /// datasheet sensitivity or amplifier gain is off; what the weighing
    /// routine finds). Default 0.
    pub loadcell_gain_error: f64,
}

impl SensorConfig {
    /// The default noise levels.
    pub const DEFAULT: SensorConfig = SensorConfig {
        noise: true,
        seed: 1,
        loadcell_sigma_n: 2.0,
        pot_sigma_m: 1e-4,
        amp_tau_s: 1.5e-4,
        loadcell_bias_n: 0.0,
        pot_bias_m: 0.0,
        loadcell_gain_error: 0.0,
    };

    /// No noise (quantisation and lag stay).
    pub const QUIET: SensorConfig = SensorConfig {
        noise: false,
        ..SensorConfig::DEFAULT
    };
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A one-shot or persistent fault in the mock I/O (for fault-injection tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct IoFaults {
    /// The e-stop input reads pressed.
    pub estop: bool,
    /// The amplifier's fault output is asserted.
    pub amp_fault: bool,
    /// Every DAC write fails.
    pub dac_error: bool,
    /// Every sensor read fails.
    pub read_error: bool,
    /// Added (wrapping) to the motor encoder counter: a step here is an
    /// encoder glitch, a ramp a runaway the plant does not follow.
    pub motor_counts_offset: u32,
    /// The load-cell ADC reads this code (stuck or saturated sensor).
    pub loadcell_code: Option<u16>,
    /// The potentiometer ADC reads this code (e.g. a rail: open wiper).
    pub pot_code: Option<u16>,
    /// The motor encoder counter reads this value (a frozen encoder).
    pub motor_counts: Option<u32>,
    /// Extra Gaussian noise on both ADC channels, codes (1 sigma; 0: none):
    /// an interference burst. Drawn from its own generator, so runs without
    /// a burst keep their noise sequence.
    pub adc_burst_sigma_codes: u16,
}

/// Sensor, DAC and amplifier models for one hopper.
#[derive(Clone, Debug)]
pub struct SimHal {
    motor: Encoder,
    height: Encoder,
    height_origin_m: f64,
    loadcell: AdcChannel,
    pot: AdcChannel,
    noise: Noise,
    amp: Amplifier,
    amp_lag: LagFactor,
    amp_enabled: bool,
    dac_code: u16,
    /// The generator of [`IoFaults::adc_burst_sigma_codes`]'s noise.
    burst_noise: Noise,
    /// The last sample read (what a frozen channel keeps reading).
    last_sample: Option<RawSample>,
    /// Injected I/O faults.
    pub faults: IoFaults,
    /// The load cell's bias against the calibration, N ([`SensorConfig`]).
    loadcell_bias_n: f64,
    /// What it reads per newton of spring force (`1 + loadcell_gain_error`).
    loadcell_scale: f64,
    /// The potentiometer's bias, m.
    pot_bias_m: f64,
}

impl SimHal {
    /// The height encoder's true origin, m: where the body really was at
    /// the firmware's first sample (by default where the calibration says;
    /// another value is a mis-calibrated height zero for the bring-up
    /// routines to find).
    pub fn with_height_origin(mut self, z_m: f64) -> Self {
        self.height_origin_m = z_m;
        self
    }

    /// Models matching `cal` (the firmware's calibration), with `cfg`'s noise.
    pub fn new(cal: &Calibration, cfg: &SensorConfig) -> Self {
        let two_pi = 2.0 * core::f64::consts::PI;
        let motor_sign = if cal.motor_counts_positive_down {
            1.0
        } else {
            -1.0
        };
        let height_sign = if cal.height_counts_positive_up {
            1.0
        } else {
            -1.0
        };
        let noise_or_zero = |s: f64| if cfg.noise { s } else { 0.0 };
        SimHal {
            motor: Encoder {
                counts_per_unit: motor_sign * f64::from(cal.motor_counts_per_rev) / two_pi,
                bits: u32::from(cal.motor_counter_bits),
            },
            height: Encoder {
                counts_per_unit: height_sign * f64::from(cal.height_counts_per_rev)
                    / (two_pi * f64::from(cal.height_pulley_radius_m)),
                bits: u32::from(cal.height_counter_bits),
            },
            height_origin_m: f64::from(cal.height_at_origin_m),
            loadcell: AdcChannel {
                bits: u32::from(cal.adc_bits),
                units_per_code: f64::from(cal.loadcell_gain_n_per_code),
                offset_code: f64::from(cal.loadcell_offset_code),
                noise_sigma: noise_or_zero(cfg.loadcell_sigma_n),
            },
            pot: AdcChannel {
                bits: u32::from(cal.adc_bits),
                units_per_code: f64::from(cal.pot_gain_m_per_code),
                offset_code: f64::from(cal.pot_offset_code),
                noise_sigma: noise_or_zero(cfg.pot_sigma_m),
            },
            noise: Noise::new(cfg.seed, cfg.noise),
            amp: Amplifier {
                dac_bits: u32::from(cal.dac_bits),
                zero_code: cal.dac_zero_code,
                amps_per_code: f64::from(cal.dac_amps_per_code),
                tau_s: cfg.amp_tau_s,
                current_a: 0.0,
            },
            amp_lag: LagFactor::default(),
            amp_enabled: false,
            dac_code: cal.dac_zero_code,
            // Enabled even with `noise: false`: a burst is a fault, not sensor noise.
            burst_noise: Noise::new(cfg.seed ^ 0x6275_7273_7400_0000, true),
            last_sample: None,
            faults: IoFaults::default(),
            loadcell_bias_n: cfg.loadcell_bias_n,
            loadcell_scale: 1.0 + cfg.loadcell_gain_error,
            pot_bias_m: cfg.pot_bias_m,
        }
    }

    /// The raw sample the sensors give for the plant's present state.
    pub fn sample(&mut self, plant: &Plant) -> RawSample {
        let s = plant.state();
        let p = plant.params();
        let leg_compression_m = match plant.mode() {
            Mode::Flight => 0.0,
            _ => (p.leg_length_m - s.z_m).max(0.0),
        };
        let motor_counts = self.motor.counter(plant.motor_angle_rad());
        let mut loadcell_code = self.loadcell.code(
            plant.spring_force_n() * self.loadcell_scale + self.loadcell_bias_n,
            &mut self.noise,
        );
        let mut pot_code = self
            .pot
            .code(leg_compression_m + self.pot_bias_m, &mut self.noise);
        if self.faults.adc_burst_sigma_codes > 0 {
            let sigma = f64::from(self.faults.adc_burst_sigma_codes);
            let full = f64::from(self.loadcell.full_scale());
            let mut burst = |code: u16| {
                let c = f64::from(code) + self.burst_noise.gaussian(sigma);
                // In 0..=full scale (an ADC cannot read outside its rails).
                libm::round(c.clamp(0.0, full)) as u16
            };
            loadcell_code = burst(loadcell_code);
            pot_code = burst(pot_code);
        }
        let f = &self.faults;
        let sample = RawSample {
            motor_counts: f.motor_counts.unwrap_or(
                self.motor
                    .wrap(motor_counts.wrapping_add(f.motor_counts_offset)),
            ),
            height_counts: self.height.counter(s.z_m - self.height_origin_m),
            loadcell_code: f.loadcell_code.unwrap_or(loadcell_code),
            pot_code: f.pot_code.unwrap_or(pot_code),
            estop_pressed: f.estop,
            amp_fault: f.amp_fault,
        };
        self.last_sample = Some(sample);
        sample
    }

    /// The last sample [`sample`](Self::sample) returned (`None` before the
    /// first): the value a channel that freezes now keeps reading.
    pub fn last_sample(&self) -> Option<RawSample> {
        self.last_sample
    }

    /// Freezes the motor encoder at the value it last read (or, before the
    /// first read, at the plant's present angle): an encoder that stops counting.
    pub fn freeze_motor_encoder(&mut self, plant: &Plant) {
        let counts = match self.last_sample {
            Some(s) => s.motor_counts,
            None => self.motor.counter(plant.motor_angle_rad()),
        };
        self.faults.motor_counts = Some(counts);
    }

    /// Sticks the load cell at the code it last read (or, before the first
    /// read, at the plant's present force without noise).
    pub fn freeze_loadcell(&mut self, plant: &Plant) {
        let code = match self.last_sample {
            Some(s) => s.loadcell_code,
            None => self
                .loadcell
                .code(plant.spring_force_n(), &mut Noise::new(0, false)),
        };
        self.faults.loadcell_code = Some(code);
    }

    /// The DAC code for 0 A.
    pub fn dac_zero_code(&self) -> u16 {
        self.amp.zero_code
    }

    /// This period's I/O on `plant`.
    pub fn io<'a>(&'a mut self, plant: &'a Plant) -> SimIo<'a> {
        SimIo { hal: self, plant }
    }

    /// The DAC's write, as both I/O views make it: refused under an
    /// injected DAC fault.
    fn write_dac(&mut self, code: u16) -> Result<(), IoError<NoPinError>> {
        if self.faults.dac_error {
            return Err(IoError::Dac);
        }
        self.dac_code = code;
        Ok(())
    }

    /// The I/O with this period's sample taken now, before the control
    /// period starts: as on the board, where the ADC and the timers have
    /// the sample ready when the control interrupt enters, so the period's
    /// timing counts the firmware's work, not the sensor models'.
    pub fn sampled(&mut self, plant: &Plant) -> SampledIo<'_> {
        let sample = self.take_sample(plant);
        self.with_sample(sample)
    }

    /// This period's sample ([`sample`](Self::sample)), or `None` under an
    /// injected read error: the sensor models' work, which an image may
    /// run outside the firmware's time ([`sampled`](Self::sampled) then
    /// [`with_sample`](Self::with_sample) in two steps).
    pub fn take_sample(&mut self, plant: &Plant) -> Option<RawSample> {
        if self.faults.read_error {
            None
        } else {
            Some(self.sample(plant))
        }
    }

    /// The I/O with `sample`, taken before the period
    /// ([`take_sample`](Self::take_sample)).
    pub fn with_sample(&mut self, sample: Option<RawSample>) -> SampledIo<'_> {
        SampledIo { hal: self, sample }
    }

    /// The load-cell and potentiometer ADC channels' largest code.
    pub fn adc_full_scale(&self) -> u16 {
        self.loadcell.full_scale()
    }

    /// The last DAC code written.
    pub fn dac_code(&self) -> u16 {
        self.dac_code
    }

    /// Whether the amplifier is enabled.
    pub fn amp_enabled(&self) -> bool {
        self.amp_enabled
    }

    /// The current command the DAC and enable ask of the amplifier, A.
    pub fn commanded_current_a(&self) -> f64 {
        if self.amp_enabled {
            self.amp.command_a(self.dac_code)
        } else {
            0.0
        }
    }

    /// Advances the amplifier's current loop by `dt_s` and returns the mean
    /// motor current over it, A (what to hand to [`Plant::advance`]).
    pub fn mean_current_a(&mut self, dt_s: f64) -> f64 {
        let cmd = self.commanded_current_a();
        self.amp.follow_cached(cmd, dt_s, &mut self.amp_lag)
    }
}

/// [`SimHal`] and the plant, as the firmware's [`HopperIo`] for one period.
pub struct SimIo<'a> {
    hal: &'a mut SimHal,
    plant: &'a Plant,
}

/// [`SimHal::sampled`]: the sample taken, the outputs to the models.
pub struct SampledIo<'a> {
    hal: &'a mut SimHal,
    sample: Option<RawSample>,
}

impl HopperIo for SampledIo<'_> {
    type Error = NoPinError;

    fn read(&mut self) -> Result<RawSample, IoError<NoPinError>> {
        self.sample.ok_or(IoError::Sensor)
    }

    fn write_dac(&mut self, code: u16) -> Result<(), IoError<NoPinError>> {
        self.hal.write_dac(code)
    }

    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<NoPinError>> {
        self.hal.amp_enabled = on;
        Ok(())
    }
}

/// The simulated hardware has no pins that can fail on their own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NoPinError;

impl HopperIo for SimIo<'_> {
    type Error = NoPinError;

    fn read(&mut self) -> Result<RawSample, IoError<NoPinError>> {
        if self.hal.faults.read_error {
            return Err(IoError::Sensor);
        }
        Ok(self.hal.sample(self.plant))
    }

    fn write_dac(&mut self, code: u16) -> Result<(), IoError<NoPinError>> {
        self.hal.write_dac(code)
    }

    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<NoPinError>> {
        self.hal.amp_enabled = on;
        Ok(())
    }
}
