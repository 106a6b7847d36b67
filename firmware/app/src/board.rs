//! The real board: clocks, encoders, ADC, DAC, amplifier pins and watchdog of
//! the hopper's STM32F405, at register level with the `stm32f4` PAC.
//!
//! [`init`] takes the device peripherals and hands back a [`Board`]:
//! [`BoardIo`] (the [`HopperIo`] the control step runs on), the independent
//! [`Watchdog`] (already running) and the [`DumpButton`].
//!
//! # Clocks
//! HSE crystal of the clock profile ([`HSE_HZ`]: 8 MHz by default, 12 MHz
//! with the `hse-12mhz` feature), PLL M = HSE / 2 MHz (2 MHz VCO input,
//! the RM0090 recommendation against jitter), N = 168 (336 MHz VCO), P = 2
//! → 168 MHz SYSCLK, Q = 7 (48 MHz, unused). AHB 168 MHz, APB1 42 MHz (its timers 84 MHz), APB2
//! 84 MHz (its timers 168 MHz). Flash: 5 wait states (168 MHz at 2.7–3.6 V),
//! prefetch and both caches on.
//!
//! Every wait for the hardware (HSE ready, PLL lock, clock switch, LSI ready,
//! watchdog register update) is a bounded poll. If the crystal does not start
//! or the PLL does not lock, the core stays on the 16 MHz HSI with all bus
//! prescalers at 1 and [`BoardIo::sysclk_hz`] says so; every derived rate
//! (control timer, ADC clock) is computed from the clock actually running.
//! Once the core runs on the PLL the clock security system is on: if the
//! crystal dies later the hardware switches the core to the HSI and raises
//! the NMI, whose handler drops AMP_EN and zeroes the DAC, then waits for
//! the watchdog's reset (which boots on the HSI: `clock-fallback` then
//! refuses arming). A clock that fell back at boot is reported the same way
//! (`hopper_control::boot::BootReport`).
//!
//! # Wiring
//! The default pin map's ([`crate::pinmap::h405`]; the Feather's is
//! [`crate::pinmap::feather`]):
//!
//! | Pin  | Peripheral / AF           | Signal                              | Direction        | Safe state / reset |
//! |------|---------------------------|-------------------------------------|------------------|--------------------|
//! | PB0  | TIM3_CH3 (AF2), push-pull | `AMP_EN`, amplifier enable, active high, through the deadman (`configure_deadman`) | output | low: a GPIO output driven low from `init`'s first step until the timer takes it, forced low; external pull-down while the pin floats (reset to `init`) |
//! | PB1  | GPIO, pull-up             | e-stop, normally-closed switch to GND; high = pressed *or* wire broken | input | reads pressed when open |
//! | PB4  | GPIO, pull-up             | amplifier fault, open-drain, active low | input        | no fault when open (see below) |
//! | PC13 | GPIO, pull-up             | dump button to GND, active low      | input            | released when open |
//! | PA4  | DAC channel 1, analog     | amplifier current command, 12 bit, buffered | analog output | zero-current code from the first instruction that touches the DAC |
//! | PA2  | ADC123_IN2, analog        | load cell                           | analog input     | — |
//! | PA3  | ADC123_IN3, analog        | leg potentiometer                   | analog input     | — |
//! | PA15 | TIM2_CH1, AF1, pull-up    | motor encoder A                     | input            | — |
//! | PB3  | TIM2_CH2, AF1, pull-up    | motor encoder B                     | input            | — |
//! | PA0  | TIM5_CH1, AF2, pull-up    | height encoder A                    | input            | — |
//! | PA1  | TIM5_CH2, AF2, pull-up    | height encoder B                    | input            | — |
//! | PA9  | USART1_TX, AF7            | host link, to the USB-UART adapter's RX, 921,600 baud 8N1 | output | idle high |
//! | PA10 | USART1_RX, AF7, pull-up   | host link, from the adapter's TX    | input            | idle high when unplugged |
//! | PA5  | DAC channel 2, analog     | the planar machine's hip current command (its amplifier enabled by AMP_EN) | analog output | zero-current code before the channel is enabled |
//! | PC6  | TIM8_CH1, AF3, pull-up    | the planar machine's hip encoder A  | input            | — |
//! | PC7  | TIM8_CH2, AF3, pull-up    | the planar machine's hip encoder B  | input            | — |
//!
//! PA15, PB3 and PB4 are JTAG pins at reset (JTDI, JTDO/SWO, NJTRST): on
//! this map, after [`init`] the board is debuggable over SWD only (PA13/PA14, untouched) and
//! has no SWO trace, which defmt over RTT does not need.
//!
//! The encoder inputs have the internal pull-ups on so that open-collector
//! encoders work and an unplugged encoder reads a steady level instead of
//! counting noise. The amplifier fault line fails *unsafe*: a broken wire
//! reads "no fault", so it is a diagnostic, not a safety function (the e-stop
//! wiring is the one that fails safe).
//!
//! # Control timing
//! The control timer (the map's: TIM4 on the H405, TIM2 on the Feather; on
//! APB1, 84 MHz) overflows at `control_hz`; its update event is its
//! TRGO, which starts ADC1's *injected* group (PA2 then PA3, 56-cycle sample
//! time at ADCCLK = PCLK2 / 4 = 21 MHz: (56 + 12) / 21 MHz = 3.2 µs each,
//! 6.5 µs for both). The end of the group (JEOC) raises the `ADC` interrupt,
//! which the application binds to its control task: the task runs once per
//! period with fresh samples in JDR1/JDR2 and calls
//! [`BoardIo::ack_control_irq`] first.
//!
//! # Encoders
//! On the default map TIM2 and TIM5 are 32-bit timers in encoder mode 3
//! (both edges of both channels, ×4) with ARR = 0xFFFF_FFFF: the raw counts
//! wrap at **32 bits**, so the calibration must say `motor_counter_bits =
//! 32` and `height_counter_bits = 32` ([`ENCODER_COUNTER_BITS`]); the
//! 16-bit defaults would reject every count above 65 535 as out of range.
//! The Feather's TIM8 and TIM3 wrap at 16 bits.
//!
//! # Watchdog
//! The IWDG runs from the LSI (nominally 32 kHz) with prescaler 4 and reload
//! 39: timeout 4 × 40 / 32 kHz = **5 ms** (3.4 ms to 9.4 ms over the LSI's
//! 17–47 kHz datasheet range). It is started at the end of [`init`] and can
//! then not be stopped by anything but a reset. It is deliberately *not*
//! frozen while a debugger halts the core: a halted core must not leave the
//! amplifier enabled with its last current command, so a breakpoint resets
//! the MCU after ~5 ms.
//!
//! Whether a period feeds it is `hopper_control::watchdog::FeedPolicy`'s
//! decision (host-tested): every completed control step does, faulted or not,
//! unless its output contradicts itself. [`Watchdog::caused_last_reset`]
//! tells the application that the IWDG caused the last reset.

use crate::serial::{RxIn, TxOut};
use hopper_control::hal::{Converters, HopperIo, IoError, PinError, PinnedIo, RawSample};
use stm32f4::stm32f405::{self as pac, Peripherals};

use crate::pinmap;

/// The DWT cycle counter as the period runner's step timer (core cycles)
/// and its clock for the period-start jitter check. A copy reads the same
/// counter (the link task times itself with one).
#[derive(Debug, Clone, Copy)]
pub struct CycleCounter {
    /// The core clock the counter runs at, Hz (0 until [`Self::set_hz`]).
    hz: u32,
    /// Core cycles a control period (0 until [`Self::set_hz`]).
    period_cycles: u32,
}

impl CycleCounter {
    /// Starts the counter (trace enabled in the DCB, CYCCNT on).
    pub fn start(dcb: &mut cortex_m::peripheral::DCB, dwt: &mut cortex_m::peripheral::DWT) -> Self {
        dcb.enable_trace();
        dwt.enable_cycle_counter();
        CycleCounter {
            hz: 0,
            period_cycles: 0,
        }
    }

    /// The core clock `init` ended up with ([`BoardIo::sysclk_hz`]) and
    /// the control rate its timer runs at: the period starts are timed
    /// with them from then on.
    pub fn set_hz(&mut self, hz: u32, control_hz: u32) {
        self.hz = hz;
        self.period_cycles = hz / control_hz.max(1);
    }
}

/// DEMCR's TRCENA: the DWT (and its cycle counter) powered.
const DEMCR_TRCENA: u32 = 1 << 24;

impl hopper_control::runner::CycleCounter for CycleCounter {
    #[inline(always)]
    fn now(&mut self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }
    fn hz(&self) -> u32 {
        self.hz
    }
    fn pacing(&self) -> hopper_control::runner::Pacing {
        if self.period_cycles == 0 {
            hopper_control::runner::Pacing::NoClock
        } else {
            hopper_control::runner::Pacing::Trigger {
                ticks: self.period_cycles,
            }
        }
    }
    /// The cycle counter, or `None` (and started again) when a debugger
    /// turned it off (DEMCR.TRCENA or DWT_CTRL.CYCCNTENA cleared): the
    /// check skips the interval rather than latch an overrun.
    fn clock(&mut self) -> Option<u32> {
        #[allow(unsafe_code)] // Reads (and a restart) of the core's debug registers.
        // SAFETY: DCB and DWT are the core's fixed register blocks; the
        // read-modify-writes only set the enables this image set at start-up
        // (nothing else in it writes them), on the control task alone.
        unsafe {
            let dcb = &*cortex_m::peripheral::DCB::PTR;
            let dwt = &*cortex_m::peripheral::DWT::PTR;
            let trace_on = dcb.demcr.read() & DEMCR_TRCENA != 0;
            let counting = dwt.ctrl.read() & 1 != 0;
            if trace_on && counting {
                return Some(cortex_m::peripheral::DWT::cycle_count());
            }
            dcb.demcr.modify(|w| w | DEMCR_TRCENA);
            dwt.ctrl.modify(|w| w | 1);
            None
        }
    }
}

/// Core clock after `init`, Hz (when the crystal starts; see [`BoardIo::sysclk_hz`]).
pub const SYSCLK_HZ: u32 = 168_000_000;

/// Width of both encoder counters in bits (the pin map's): the value for
/// the calibration's `motor_counter_bits` and `height_counter_bits`.
pub const ENCODER_COUNTER_BITS: u8 = pinmap::ENCODER_COUNTER_BITS;

/// The core clock when the crystal or the PLL fails: the internal HSI oscillator.
const HSI_HZ: u32 = 16_000_000;
/// The crystal on the board: the clock profile, a cargo feature of
/// `hopper-app`. `hse-8mhz` (the default): the Olimex STM32-H405 and most
/// F405 boards with an 8 MHz crystal; `hse-12mhz`: the Adafruit Feather
/// STM32F405 Express and the MicroPython pyboard (v1.1). Every other rate
/// follows from it: the PLL input is 2 MHz on both.
pub const HSE_HZ: u32 = if cfg!(feature = "hse-12mhz") {
    12_000_000
} else {
    8_000_000
};
/// The profile's name, for the logs and the docs.
pub const CLOCK_PROFILE: &str = if cfg!(feature = "hse-12mhz") {
    "hse-12mhz"
} else {
    "hse-8mhz"
};
/// PLL input divider: the crystal over 2 MHz (8 MHz / 4, 12 MHz / 6), the
/// VCO input RM0090 recommends against jitter.
const PLL_M: u8 = (HSE_HZ / 2_000_000) as u8;
/// PLL multiplier: 2 MHz × 168 = 336 MHz VCO.
const PLL_N: u16 = 168;
/// PLL system-clock divider (the PAC's `div2`): 336 / 2 = 168 MHz.
const PLL_P: u32 = 2;
/// PLL 48 MHz-domain divider: 336 / 7 = 48 MHz (USB/SDIO, unused, but kept legal).
const PLL_Q: u8 = 7;

// The PLL figures are the ones RM0090 allows (M 2..=63, N 50..=432, Q 2..=15,
// VCO input 1–2 MHz, VCO output 100–432 MHz) and give SYSCLK_HZ.
const _: () = {
    assert!(PLL_M >= 2 && PLL_M <= 63);
    assert!(PLL_N >= 50 && PLL_N <= 432);
    assert!(PLL_Q >= 2 && PLL_Q <= 15);
    let vco_in = HSE_HZ / PLL_M as u32;
    assert!(vco_in >= 1_000_000 && vco_in <= 2_000_000);
    let vco = vco_in * PLL_N as u32;
    assert!(vco >= 100_000_000 && vco <= 432_000_000);
    assert!(vco / PLL_P == SYSCLK_HZ);
    assert!(vco / PLL_Q as u32 <= 48_000_000);
};

/// APB1 clock with the PLL: SYSCLK / 4 (its maximum is 42 MHz).
const PLL_PCLK1_HZ: u32 = SYSCLK_HZ / 4;

/// Polls of a ready flag before giving up. One poll is a volatile load, a test
/// and a branch (at least 4 cycles), so at the 16 MHz HSI this is at least
/// 100 ms: far more than the crystal start-up (typically 2 ms) or PLL lock
/// (~0.2 ms) need, and short enough that a dead crystal only delays start-up.
/// The watchdog's waits run at 168 MHz, where it is still ≥ 9.5 ms against
/// the LSI's ~0.3 ms.
const READY_POLLS: u32 = 400_000;

/// Slowest control rate `init` accepts, Hz (slower requests are raised to it).
const MIN_CONTROL_HZ: u32 = 1;
/// Fastest control rate `init` accepts, Hz (faster requests are lowered to
/// it): the two conversions take 6.5 µs at 168 MHz and 34 µs on the HSI
/// fallback (ADCCLK 4 MHz), both well inside a 50 µs period.
const MAX_CONTROL_HZ: u32 = 20_000;

/// Largest 12-bit DAC code.
const DAC_MAX_CODE: u16 = 0x0FFF;
/// Zero-current code used when `init` gets an impossible one: mid-scale, the
/// zero of a symmetric ±10 V amplifier input (and the calibration default).
const DAC_FALLBACK_ZERO_CODE: u16 = 2048;

/// IWDG reload value: (39 + 1) × 4 / 32 kHz = 5 ms.
const IWDG_RELOAD: u16 = 39;
const _: () = assert!(IWDG_RELOAD <= 0x0FFF);

/// Everything the RTIC app needs from the board.
pub struct Board {
    /// Sensors, DAC and amplifier enable: the control step's [`HopperIo`].
    pub io: BoardIo,
    /// The running independent watchdog; give it to the control task only.
    pub watchdog: Watchdog,
    /// The dump button (the pin map's: PC13 on the H405).
    pub dump_button: DumpButton,
    /// The host link's USART (the pin map's), receiving.
    pub serial: crate::serial::Serial<'static>,
    /// What init found: the reset causes, the brown-out reset, the clock.
    pub boot: hopper_control::boot::BootReport,
    /// The saved calibration: a pending save written, the record read.
    pub stored: crate::flash::AtBoot,
}

/// The clocks `init` ended up with.
#[derive(Debug, Clone, Copy)]
struct Clocks {
    /// The crystal as measured against the HSI, Hz (0: not measured).
    hse_measured_hz: u32,
    /// Core and AHB clock, Hz.
    sysclk_hz: u32,
    /// Clock of the APB1 timers (TIM2..TIM7, TIM12..TIM14), Hz.
    apb1_timer_hz: u32,
    /// APB1 clock (USART2, USART3), Hz.
    pclk1_hz: u32,
    /// APB2 clock (USART1), Hz.
    pclk2_hz: u32,
}

/// The control timer's update (and TRGO) at `control_hz` from a
/// `timer_hz` clock, left stopped; the rate it will run at, rounded to the
/// nearest Hz. A macro: the maps' control timers (TIM4, TIM2) are
/// different register blocks with the same fields.
macro_rules! configure_control_timer {
    ($tim:expr, $timer_hz:expr, $control_hz:expr) => {{
        let tim = $tim;
        let (psc, arr, actual_hz) = control_timer_setup($timer_hz, $control_hz);
        tim.cr1().modify(|_, w| w.cen().disabled());
        tim.psc().write(|w| w.psc().set(psc));
        tim.arr().write(|w| w.arr().set(arr.into()));
        tim.cnt().write(|w| w.cnt().set(0));
        // URS: only overflows set the update flag, not the UG below.
        tim.cr1()
            .modify(|_, w| w.urs().counter_only().arpe().enabled());
        // UG loads the prescaler now (it is otherwise only loaded at the
        // first overflow, which would make the first period 1/(PSC+1) too
        // short).
        tim.egr().write(|w| w.ug().update());
        tim.cr2().modify(|_, w| w.mms().update());
        actual_hz
    }};
}

/// Configures the board; the amplifier is disabled (AMP_EN low) and the DAC at
/// the zero-current code before anything else is touched.
///
/// `control_hz` is clamped to 1..=20 000 Hz; [`BoardIo::control_hz`] gives the
/// rate the timer actually runs at. `dac_zero_code` above 4095 (which a
/// validated calibration never has) is replaced by mid-scale, 2048.
///
/// Starts the control timer (the ADC interrupt then fires every period once the
/// application unmasks it) and, last, the watchdog: the first
/// [`Watchdog::feed`] must come within ~5 ms of this function returning.
pub fn init(
    dp: Peripherals,
    control_hz: u32,
    dac_zero_code: u16,
    link: (RxIn<'static>, TxOut<'static>),
) -> Board {
    let zero_code = if dac_zero_code <= DAC_MAX_CODE {
        dac_zero_code
    } else {
        DAC_FALLBACK_ZERO_CODE
    };

    // 1. AMP_EN (the pin map's, PB0 on the H405): latch the output low *before* making the pin an output,
    //    so it never drives high, not even for one cycle.
    pinmap::amp_en_low(&dp.RCC, &dp.GPIOB);

    // 2. DAC channel 1 (PA4) at the zero-current code. PA4 goes analog first
    //    (RM0090: avoids the digital input's parasitic consumption); with no
    //    trigger (TEN1 = 0) DHR moves to the output one APB1 cycle after each
    //    write, so the code is written before and again after enabling.
    dp.RCC.apb1enr().modify(|_, w| w.dacen().enabled());
    let _ = dp.RCC.apb1enr().read();
    dp.GPIOA.pupdr().modify(|_, w| w.pupdr4().floating());
    dp.GPIOA.moder().modify(|_, w| w.moder4().analog());
    dp.DAC.dhr12r1().write(|w| w.daccdhr().set(zero_code));
    dp.DAC.cr().modify(|_, w| {
        w.ten1()
            .disabled()
            .wave1()
            .disabled()
            .dmaen1()
            .disabled()
            .boff1()
            .enabled()
            .en1()
            .enabled()
    });
    dp.DAC.dhr12r1().write(|w| w.daccdhr().set(zero_code));
    // Channel 2 (PA5), the planar machine's hip amplifier, the same way.
    // Its amplifier's enable is AMP_EN too (the pin map's note).
    dp.GPIOA.pupdr().modify(|_, w| w.pupdr5().floating());
    dp.GPIOA.moder().modify(|_, w| w.moder5().analog());
    dp.DAC.dhr12r2().write(|w| w.daccdhr().set(zero_code));
    dp.DAC.cr().modify(|_, w| {
        w.ten2()
            .disabled()
            .wave2()
            .disabled()
            .dmaen2()
            .disabled()
            .boff2()
            .enabled()
            .en2()
            .enabled()
    });
    dp.DAC.dhr12r2().write(|w| w.daccdhr().set(zero_code));

    // 3. The other pins.
    pinmap::configure_inputs(&dp.GPIOB, &dp.GPIOC);
    pinmap::configure_analog_and_encoder_pins(&dp.GPIOA, &dp.GPIOB, &dp.GPIOC);

    // 4. Clocks. Everything timed below derives from the clock that runs.
    let clocks = configure_clocks(&dp.RCC, &dp.FLASH, &dp.PWR, &dp.TIM11);

    // 5. Encoders.
    pinmap::enable_clocks(&dp.RCC);
    // Typed by the map's names: a map whose macro and names disagree does
    // not compile (its `adc_trigger` sits beside its `ControlTimer`).
    let (motor_counter, height_counter, hip_counter, control_timer): (
        pinmap::MotorCounter,
        pinmap::HeightCounter,
        pinmap::HipCounter,
        pinmap::ControlTimer,
    ) = pinmap::take_counters!(dp);
    let (deadman_timer, link_usart) = pinmap::take_deadman_and_link!(dp);
    pinmap::configure_encoders(&motor_counter, &height_counter, &hip_counter);

    // 6. The control timer (the map's: TIM4 on the H405) at the control
    //    rate, stopped; configured while the ADC's trigger input is still
    //    disabled, so loading it cannot trigger.
    let control_hz = configure_control_timer!(&control_timer, clocks.apb1_timer_hz, control_hz);

    // 6b. The hardware deadman: AMP_EN becomes the deadman timer's
    //     output, forced low until the first enabled period retriggers it.
    let deadman = configure_deadman(
        deadman_timer,
        &dp.GPIOB,
        &dp.DBGMCU,
        clocks.apb1_timer_hz,
        control_hz,
    );

    // 7. ADC1 injected group, triggered by the control timer's TRGO,
    //    interrupt at its end.
    configure_adc(&dp.ADC_COMMON, &dp.ADC1);

    // 8. Start the control timer: the first trigger comes one period later
    //    and finds the ADC powered and settled.
    control_timer.cr1().modify(|_, w| w.cen().enabled());

    // 9. The host link: the pin map's USART.
    let serial = crate::serial::Serial::new(
        link_usart,
        &dp.RCC,
        &dp.GPIOA,
        &dp.GPIOB,
        clocks.link_bus_hz(),
        link.0,
        link.1,
    );

    // The brown-out reset level in the option bytes (BOR_LEV), before the
    // watchdog so that the watchdog's first reload stays init's last act.
    let brown_out_reset_on = hopper_control::boot::BootReport::brown_out_reset_on_from_optcr(
        dp.FLASH.optcr().read().bits(),
    );

    // The saved calibration: a save waiting in RAM is written now (a
    // sector erase stalls the core for a second or two: before the
    // watchdog, with the amplifier off), then the record is read.
    let stored = crate::flash::at_boot(&dp.FLASH, &dp.PWR);

    // 10. The watchdog, last: from here on the control task must run.
    let watchdog = Watchdog::start(dp.IWDG, &dp.RCC);
    let boot = hopper_control::boot::BootReport {
        resets: watchdog.reset_causes,
        brown_out_reset_on,
        clock_as_configured: clocks.sysclk_hz == SYSCLK_HZ,
        sysclk_hz: clocks.sysclk_hz,
        hse_expected_hz: HSE_HZ,
        hse_measured_hz: clocks.hse_measured_hz,
    };

    Board {
        stored,
        io: BoardIo {
            io: PinnedIo::new(
                BoardConverters {
                    motor: motor_counter,
                    height: height_counter,
                    adc: dp.ADC1,
                    dac: dp.DAC,
                },
                pinmap::estop(),
                pinmap::amp_fault(),
                deadman,
            ),
            sysclk_hz: clocks.sysclk_hz,
            control_hz,
        },
        watchdog,
        dump_button: DumpButton {
            pin: pinmap::dump_button(),
            // Start as "held": a button held (or shorted) at boot must be
            // seen released before a press counts.
            pressed: true,
            last_sample: true,
        },
        serial,
        boot,
    }
}

/// The hardware-in-the-loop image's board (`hopper-hil`): the host sends
/// each period's sensor sample over the link and takes the DAC code back,
/// so of the board only the clocks, the link, the e-stop input and the
/// amplifier-enable output are in use.
pub struct HilBoard {
    /// The e-stop input and AMP_EN, as a plain output.
    pub pins: HilPins,
    /// The host link's USART (the pin map's).
    pub serial: crate::serial::Serial<'static>,
    /// What init found (no watchdog runs: the reset causes are read).
    pub boot: hopper_control::boot::BootReport,
    /// Core clock, Hz.
    pub sysclk_hz: u32,
    /// TIM5, clocked and idle (no height encoder in this image): the control
    /// interrupt's counter where the core has no cycle counter (QEMU).
    pub tim5: pac::TIM5,
}

/// The board's e-stop input and AMP_EN in the loop (PB1 and PB0 on the
/// default pin map).
///
/// AMP_EN is the hardware deadman, as on the robot, with a
/// window of [`HIL_DEADMAN_WINDOW_US`] of wall-clock time instead of three
/// control periods: the host paces the periods (hundreds to thousands a
/// second), and when it stops sending (a crash, an unplugged cable, the
/// end of a run) the enable falls by itself within the window, whatever
/// the firmware does. A period later than that latches `amp-fault`. The
/// e-stop input is the board's, so a bench e-stop disarms the run as it
/// would the robot.
#[derive(Debug)]
pub struct HilPins {
    estop: pinmap::Estop,
    enable: Deadman,
}

/// The HIL image's deadman window, us (the longest the 16-bit timer at
/// 1 MHz holds is 65.5 ms).
pub const HIL_DEADMAN_WINDOW_US: u32 = 50_000;

impl hopper_robot_link::hil::HilPins for HilPins {
    type Error = DeadmanLapsed;

    fn estop_pressed(&mut self) -> bool {
        // Normally-closed to GND with a pull-up: high = pressed or broken.
        embedded_hal::digital::InputPin::is_high(&mut self.estop).unwrap_or(true)
    }

    fn set_amp_enabled(&mut self, on: bool) -> Result<(), Self::Error> {
        self.enable.set(on)
    }
}

/// Brings up the HIL image's board: AMP_EN low first, the inputs, the
/// clocks (the HSI on a failed crystal, and in QEMU), the link on the pin
/// map's USART.
/// The deadman on AMP_EN with a wall-clock window ([`HilPins`]); no
/// converters, encoders, control timer or watchdog: the periods come from
/// the host.
pub fn init_hil(dp: Peripherals, link: (RxIn<'static>, TxOut<'static>)) -> HilBoard {
    pinmap::amp_en_low(&dp.RCC, &dp.GPIOB);
    pinmap::configure_inputs(&dp.GPIOB, &dp.GPIOC);
    let clocks = configure_clocks(&dp.RCC, &dp.FLASH, &dp.PWR, &dp.TIM11);
    // The deadman with a wall-clock window (`HilPins`): three "periods" of
    // a third of the window each.
    pinmap::enable_hil_clocks(&dp.RCC);
    let (deadman_timer, link_usart) = pinmap::take_deadman_and_link!(dp);
    let deadman = configure_deadman(
        deadman_timer,
        &dp.GPIOB,
        &dp.DBGMCU,
        clocks.apb1_timer_hz,
        hopper_control::deadman::WINDOW_PERIODS * 1_000_000 / HIL_DEADMAN_WINDOW_US,
    );
    let serial = crate::serial::Serial::new(
        link_usart,
        &dp.RCC,
        &dp.GPIOA,
        &dp.GPIOB,
        clocks.link_bus_hz(),
        link.0,
        link.1,
    );
    let brown_out_reset_on = hopper_control::boot::BootReport::brown_out_reset_on_from_optcr(
        dp.FLASH.optcr().read().bits(),
    );
    let boot = hopper_control::boot::BootReport {
        resets: take_reset_causes(&dp.RCC),
        brown_out_reset_on,
        clock_as_configured: clocks.sysclk_hz == SYSCLK_HZ,
        sysclk_hz: clocks.sysclk_hz,
        hse_expected_hz: HSE_HZ,
        hse_measured_hz: clocks.hse_measured_hz,
    };
    HilBoard {
        pins: HilPins {
            estop: pinmap::estop(),
            enable: deadman,
        },
        serial,
        boot,
        sysclk_hz: clocks.sysclk_hz,
        tim5: dp.TIM5,
    }
}

/// Every reset flag of RCC_CSR, then cleared (RMVF), so that the next
/// reset reports only its own cause.
fn take_reset_causes(rcc: &pac::RCC) -> hopper_control::boot::ResetCauses {
    let causes = hopper_control::boot::ResetCauses::from_rcc_csr(rcc.csr().read().bits());
    rcc.csr().modify(|_, w| w.rmvf().clear());
    causes
}

/// The deadman on AMP_EN (`hopper_control::deadman`, docs/board.md): the
/// pin map's timer ticking at 1 MHz, one-pulse, its window
/// [`deadman::window_ticks`] of the control rate; its channel forced low,
/// then AMP_EN handed from its GPIO output (driven low since step 1) to
/// the timer's channel, the AF number before the mode, so the pin never
/// drives high. The debugger's freeze of the timer (DBGMCU_APB1_FZ, which
/// a system reset does not clear) is cleared: a halted core drops the
/// enable too.
///
/// [`deadman::window_ticks`]: hopper_control::deadman::window_ticks
fn configure_deadman(
    tim: pinmap::DeadmanTimer,
    gpiob: &pac::GPIOB,
    dbgmcu: &pac::DBGMCU,
    timer_hz: u32,
    control_hz: u32,
) -> Deadman {
    pinmap::unfreeze_timers(dbgmcu);
    let deadman = Deadman::new(pinmap::DeadmanRegs(tim), timer_hz, control_hz);
    pinmap::amp_en_to_deadman(gpiob);
    deadman
}

/// Polls `ready` up to [`READY_POLLS`] times; whether it became true.
fn wait_for(mut ready: impl FnMut() -> bool) -> bool {
    for _ in 0..READY_POLLS {
        if ready() {
            return true;
        }
    }
    ready()
}

/// HSE → PLL → 168 MHz, or the HSI at 16 MHz if that fails. Never hangs.
fn configure_clocks(
    rcc: &pac::RCC,
    flash: &pac::FLASH,
    pwr: &pac::PWR,
    tim11: &pac::TIM11,
) -> Clocks {
    let mut hsi = Clocks {
        hse_measured_hz: 0,
        sysclk_hz: HSI_HZ,
        apb1_timer_hz: HSI_HZ,
        pclk1_hz: HSI_HZ,
        pclk2_hz: HSI_HZ,
    };

    // Start from a known state: on the HSI, PLL off (a debugger or bootloader
    // may have left the PLL running, and PLLCFGR must not change while it is on).
    rcc.cr().modify(|_, w| w.hsion().on());
    if !wait_for(|| rcc.cr().read().hsirdy().is_ready()) {
        // The HSI is what the core runs on after reset; if it reports not
        // ready, touch nothing more.
        return hsi;
    }
    rcc.cfgr().modify(|_, w| w.sw().hsi());
    if !wait_for(|| rcc.cfgr().read().sws().is_hsi()) {
        return hsi;
    }
    rcc.cfgr()
        .modify(|_, w| w.hpre().div1().ppre1().div1().ppre2().div1());
    rcc.cr().modify(|_, w| w.pllon().off());
    if !wait_for(|| rcc.cr().read().pllrdy().is_not_ready()) {
        return hsi;
    }

    // Voltage scale 1, needed above 144 MHz (the F405's reset value, set anyway).
    rcc.apb1enr().modify(|_, w| w.pwren().enabled());
    let _ = rcc.apb1enr().read();
    pwr.cr().modify(|_, w| w.vos().scale1());

    // Crystal, not an external clock signal. HSEBYP is only writable while
    // the HSE is off, so it goes in its own write, before HSEON.
    rcc.cr().modify(|_, w| w.hsebyp().not_bypassed());
    rcc.cr().modify(|_, w| w.hseon().on());
    if !wait_for(|| rcc.cr().read().hserdy().is_ready()) {
        rcc.cr().modify(|_, w| w.hseon().off());
        return hsi;
    }

    // The crystal against the HSI, before the PLL multiplies it: a crystal
    // other than the profile's (a 12 MHz board on the 8 MHz build) would
    // run the core at 1.5 times 168 MHz. Then the HSI stays, and arming is
    // refused (`crystal-not-the-profiles`).
    hsi.hse_measured_hz = measure_hse(rcc, tim11);
    if !hopper_control::boot::Crystal::matches(hsi.hse_measured_hz, HSE_HZ) {
        rcc.cr().modify(|_, w| w.hseon().off());
        return hsi;
    }

    write_pll_config(rcc);
    rcc.cr().modify(|_, w| w.pllon().on());
    if !wait_for(|| rcc.cr().read().pllrdy().is_ready()) {
        rcc.cr().modify(|_, w| w.pllon().off().hseon().off());
        return hsi;
    }

    // Wait states before the clock goes up, and checked: RM0090 (flash read
    // access latency) asks to read ACR back before raising the frequency.
    flash.acr().modify(|_, w| {
        w.latency()
            .ws5()
            .prften()
            .enabled()
            .icen()
            .enabled()
            .dcen()
            .enabled()
    });
    if !flash.acr().read().latency().is_ws5() {
        rcc.cr().modify(|_, w| w.pllon().off().hseon().off());
        return hsi;
    }

    // Bus prescalers before the switch, so APB1 never exceeds 42 MHz.
    rcc.cfgr()
        .modify(|_, w| w.hpre().div1().ppre1().div4().ppre2().div2());
    rcc.cfgr().modify(|_, w| w.sw().pll());
    if !wait_for(|| rcc.cfgr().read().sws().is_pll()) {
        rcc.cfgr().modify(|_, w| w.sw().hsi());
        // Best effort: if the switch back did not happen either, the PLL and
        // the bus prescalers stay as they are (turning the PLL off or the
        // prescalers down under a core on the PLL would stop it or overclock
        // APB1), and the reported rates are then wrong.
        if wait_for(|| rcc.cfgr().read().sws().is_hsi()) {
            rcc.cfgr().modify(|_, w| w.ppre1().div1().ppre2().div1());
            rcc.cr().modify(|_, w| w.pllon().off().hseon().off());
        }
        return hsi;
    }

    // The clock security system: if the crystal stops from now on, the
    // hardware switches the core to the HSI and raises the NMI, whose
    // handler drops AMP_EN and zeroes the DAC (`main.rs`, `NonMaskableInt`).
    rcc.cr().modify(|_, w| w.csson().on());

    Clocks {
        hse_measured_hz: hsi.hse_measured_hz,
        sysclk_hz: SYSCLK_HZ,
        // APB1 prescaler ≠ 1: its timers run at twice PCLK1.
        apb1_timer_hz: 2 * PLL_PCLK1_HZ,
        pclk1_hz: PLL_PCLK1_HZ,
        pclk2_hz: SYSCLK_HZ / 2,
    }
}

impl Clocks {
    /// The clock of the pin map's link USART, Hz.
    fn link_bus_hz(&self) -> u32 {
        match pinmap::LINK_BUS {
            pinmap::Bus::Apb1 => self.pclk1_hz,
            pinmap::Bus::Apb2 => self.pclk2_hz,
        }
    }
}

/// The crystal's divider for the measurement (RCC_CFGR.RTCPRE): 8 MHz / 8
/// = 1 MHz, within TIM11's reach at 16 MHz.
const MEASURE_DIVIDER: u32 = 8;
/// Captures every 8th edge (IC1PSC = /8): 128 HSI counts at 8 MHz.
const MEASURE_EDGES: u32 = 8;
/// Captures averaged.
const MEASURE_CAPTURES: u32 = 8;

/// The crystal's frequency against the HSI, Hz (0 when no capture came):
/// HSE / RTCPRE is routed to TIM11's channel 1 (TIM11_OR.TI1_RMP = 0b10,
/// RM0090 section 18.5.9), captured on every 8th rising edge with TIM11
/// counting APB2, the HSI at 16 MHz here (the core is still on it).
#[allow(unsafe_code)] // RTCPRE and TIM11's registers are written as raw words.
fn measure_hse(rcc: &pac::RCC, tim11: &pac::TIM11) -> u32 {
    rcc.apb2enr()
        .modify(|r, w| unsafe { w.bits(r.bits() | (1 << 18)) });
    let _ = rcc.apb2enr().read();
    // RTCPRE (bits 20:16): HSE / 8. It only feeds the RTC clock mux and
    // this capture; the RTC is unused.
    rcc.cfgr()
        .modify(|r, w| unsafe { w.bits((r.bits() & !(0x1F << 16)) | (MEASURE_DIVIDER << 16)) });
    // SAFETY (all the writes below): TIM11's documented register values;
    // the timer is unused elsewhere and is switched off again at the end.
    tim11.or().write(|w| unsafe { w.bits(0b10) }); // TI1 = HSE_RTC
    tim11.psc().write(|w| unsafe { w.bits(0) });
    tim11.arr().write(|w| unsafe { w.bits(0xFFFF) });
    // CC1S = 01 (IC1 on TI1), IC1PSC = 11 (every 8th edge), no filter.
    tim11
        .ccmr1_input()
        .write(|w| unsafe { w.bits(0b01 | (0b11 << 2)) });
    tim11.ccer().write(|w| unsafe { w.bits(1) }); // CC1E, rising edge
    tim11.egr().write(|w| unsafe { w.bits(1) }); // UG: load PSC
    tim11.sr().write(|w| unsafe { w.bits(0) });
    tim11.cr1().write(|w| unsafe { w.bits(1) }); // CEN
    let capture = || -> Option<u32> {
        if wait_for(|| tim11.sr().read().bits() & (1 << 1) != 0) {
            // Reading CCR1 clears CC1IF.
            let ccr = tim11.ccr1().read().bits() & 0xFFFF;
            // CC1OF: a capture came before this one was read, so the
            // interval would span two: useless (a 16 MHz crystal missing
            // every other capture would read as 8 MHz).
            let sr = tim11.sr().read().bits();
            tim11.sr().write(|w| unsafe { w.bits(!(1 << 9) & 0xFFFF) });
            (sr & (1 << 9) == 0).then_some(ccr)
        } else {
            None
        }
    };
    let mut total = 0u32;
    let mut ok = 0u32;
    let (mut shortest, mut longest) = (u32::MAX, 0u32);
    let mut last = capture();
    for _ in 0..MEASURE_CAPTURES {
        let next = capture();
        if let (Some(a), Some(b)) = (last, next) {
            let interval = b.wrapping_sub(a) & 0xFFFF;
            total += interval;
            shortest = shortest.min(interval);
            longest = longest.max(interval);
            ok += 1;
        }
        last = next;
    }
    // Every interval the same to a count or two (HSI jitter), all of them
    // there: else no measurement (the core then stays on the HSI).
    if ok < MEASURE_CAPTURES || longest > shortest + 2 {
        ok = 0;
    }
    tim11.cr1().write(|w| unsafe { w.bits(0) });
    tim11.or().write(|w| unsafe { w.bits(0) });
    rcc.apb2enr()
        .modify(|r, w| unsafe { w.bits(r.bits() & !(1 << 18)) });
    if ok == 0 {
        return 0;
    }
    // All the captures' edges over all their counts.
    hopper_control::boot::Crystal {
        timer_hz: HSI_HZ,
        divider: MEASURE_DIVIDER,
        edges: MEASURE_EDGES * ok,
    }
    .hz_from_ticks(total)
}

/// Writes PLLCFGR: source HSE, M, N, P, Q as the constants above. PLL must be off.
#[allow(unsafe_code)] // PLLM/PLLN/PLLQ have no safe writer in the PAC.
fn write_pll_config(rcc: &pac::RCC) {
    rcc.pllcfgr().modify(|_, w| {
        // SAFETY: the values are checked at compile time (the `const _`
        // block above) to be inside the ranges RM0090's RCC_PLLCFGR allows,
        // and the PLL is off (the caller waited for PLLRDY = 0), the only
        // time PLLCFGR may be written.
        unsafe { w.pllm().bits(PLL_M).plln().bits(PLL_N).pllq().bits(PLL_Q) }
            .pllp()
            .div2()
            .pllsrc()
            .hse()
    });
}

/// ADC1: 12 bit, right aligned, injected group load cell → JDR1,
/// potentiometer → JDR2 (the pin map's channels: PA2 and PA3 on the H405),
/// triggered by the control timer's TRGO (rising edge), interrupt at the group's end.
fn configure_adc(common: &pac::ADC_COMMON, adc: &pac::ADC1) {
    adc.cr2().modify(|_, w| w.adon().disabled());
    // ADCCLK = PCLK2 / 4: 21 MHz at 168 MHz (the F405's maximum is 36 MHz).
    common.ccr().modify(|_, w| w.adcpre().div4());
    pinmap::set_sample_times(adc);
    set_injected_sequence(adc);
    // SCAN: convert the whole injected group on one trigger (JEOC at its end).
    adc.cr1().modify(|_, w| {
        w.res()
            .twelve_bit()
            .scan()
            .enabled()
            .jauto()
            .disabled()
            .jdiscen()
            .disabled()
            .eocie()
            .disabled()
            .jeocie()
            .enabled()
    });
    adc.cr2().modify(|_, w| {
        w.align().right().cont().single().exten().disabled();
        pinmap::adc_trigger(w).jexten().rising_edge()
    });
    // A flag left set would fire the interrupt as soon as it is unmasked.
    adc.sr().write(|w| w.jeoc().clear().jstrt().clear());
    // Powered on now; it needs t_STAB (3 µs) before converting, far less
    // than the first control period.
    adc.cr2().modify(|_, w| w.adon().enabled());
}

/// JSQR: two conversions (JL = 1). With JL = 1 the ADC converts JSQ3 then
/// JSQ4 and stores them in JDR1 then JDR2 (RM0090, ADC_JSQR; ST's HAL
/// places rank 1 of a 2-long group in JSQ3 the same way).
#[allow(unsafe_code)] // The JSQx fields have no safe writer in the PAC.
fn set_injected_sequence(adc: &pac::ADC1) {
    adc.jsqr().write(|w| {
        // SAFETY: the map's channels (2 and 3, or 14 and 15) exist on ADC1
        // (the field takes 0..=18) and
        // are what JSQ3/JSQ4 hold; the ADC is off (ADON = 0) while it is set.
        unsafe {
            w.jsq3()
                .bits(pinmap::LOADCELL_CHANNEL)
                .jsq4()
                .bits(pinmap::POT_CHANNEL)
        }
        .jl()
        .set(1)
    });
}

/// Prescaler, auto-reload and resulting rate for a 16-bit timer: the smallest
/// prescaler whose period fits 16 bits, for the best rate resolution.
fn control_timer_setup(timer_hz: u32, control_hz: u32) -> (u16, u16, u32) {
    let hz = control_hz.clamp(MIN_CONTROL_HZ, MAX_CONTROL_HZ);
    // timer_hz >= 16 MHz, hz <= 20 kHz: at least 800 ticks per period.
    let ticks = (timer_hz / hz).max(1);
    let prescale = (ticks - 1) / 0x1_0000 + 1; // 1..=65_536 for any u32 ticks
    let period = (ticks / prescale).clamp(1, 0x1_0000);
    let psc = u16::try_from(prescale - 1).unwrap_or(u16::MAX);
    let arr = u16::try_from(period - 1).unwrap_or(u16::MAX);
    let divisor = u64::from(prescale) * u64::from(period);
    let actual = (u64::from(timer_hz) + divisor / 2) / divisor;
    (psc, arr, u32::try_from(actual).unwrap_or(u32::MAX))
}

/// Sensors, DAC and amplifier enable of the real board.
///
/// [`HopperIo::read`] is meant for the control task, right after
/// [`ack_control_irq`](Self::ack_control_irq): then JDR1/JDR2 hold the
/// samples of this period and the next conversion is a full period away.
#[derive(Debug)]
pub struct BoardIo {
    /// The board's parts as the hopper's I/O (`hopper_control::hal::PinnedIo`):
    /// the converters and counters, the e-stop and amplifier-fault inputs,
    /// the deadman on AMP_EN, each where the pin map ([`crate::pinmap`])
    /// puts it.
    io: PinnedIo<BoardConverters, pinmap::Estop, pinmap::AmpFault, Deadman>,
    /// Core clock that `init` achieved.
    sysclk_hz: u32,
    /// Control (control timer update) rate that `init` achieved.
    control_hz: u32,
}

/// The converters and counters (what embedded-hal has no traits for): the
/// encoders on the pin map's counters (TIM2 and TIM5 on the H405), the load cell and the
/// potentiometer on ADC1's injected group, the current command on DAC
/// channel 1.
#[derive(Debug)]
pub struct BoardConverters {
    motor: pinmap::MotorCounter,
    height: pinmap::HeightCounter,
    adc: pac::ADC1,
    dac: pac::DAC,
}

impl Converters for BoardConverters {
    fn counters(&mut self) -> (u32, u32) {
        (
            self.motor.cnt().read().bits(),
            self.height.cnt().read().bits(),
        )
    }

    fn codes(&mut self) -> (u16, u16) {
        (
            self.adc.jdr1().read().jdata().bits(),
            self.adc.jdr2().read().jdata().bits(),
        )
    }

    /// Writes DHR12R1; codes above 4095 are refused, not truncated.
    fn write_dac(&mut self, code: u16) -> bool {
        if code > DAC_MAX_CODE {
            return false;
        }
        self.dac.dhr12r1().write(|w| w.daccdhr().set(code));
        true
    }
}

/// The hardware deadman on AMP_EN (the pin map's timer and channel,
/// [`hopper_control::deadman::Deadman`]'s writes) as the amplifier enable.
pub type Deadman = hopper_control::deadman::Deadman<pinmap::DeadmanRegs>;

impl BoardIo {
    /// Clears the control interrupt's flag (ADC injected end of conversion); returns whether it was set.
    pub fn ack_control_irq(&mut self) -> bool {
        let adc = &self.io.converters.adc;
        let set = adc.sr().read().jeoc().is_complete();
        if set {
            // rc_w0 register: the PAC writes 1 to the other flags (no effect)
            // and 0 to JEOC (and JSTRT, which is set with it), so nothing else
            // is cleared by accident.
            adc.sr().write(|w| w.jeoc().clear().jstrt().clear());
        }
        set
    }

    /// Core clock, Hz: [`SYSCLK_HZ`], or 16 000 000 if the crystal or PLL
    /// failed at start-up and the board runs on the HSI.
    pub fn sysclk_hz(&self) -> u32 {
        self.sysclk_hz
    }

    /// Control (ADC trigger) rate the timer runs at, Hz, rounded to the
    /// nearest Hz: the requested rate, clamped to 1..=20 000 Hz, up to the
    /// timer's integer division.
    pub fn control_hz(&self) -> u32 {
        self.control_hz
    }
}

/// The deadman's window lapsed between two enabled periods
/// ([`Deadman`]).
pub use hopper_control::deadman::Lapsed as DeadmanLapsed;

impl HopperIo for BoardIo {
    type Error = PinError<DeadmanLapsed>;

    /// Encoder counters, the injected ADC codes of this period, e-stop and fault pins.
    fn read(&mut self) -> Result<RawSample, IoError<Self::Error>> {
        self.io.read()
    }

    fn write_dac(&mut self, code: u16) -> Result<(), IoError<Self::Error>> {
        self.io.write_dac(code)
    }

    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<Self::Error>> {
        self.io.set_amp_enabled(on)
    }
}

/// The independent watchdog, running (about 5 ms timeout; see the module docs).
///
/// Once started it cannot be stopped except by a reset. Only the control
/// task may own and feed it: then a control task that stops running (hang,
/// overrun storm, interrupt lost) resets the MCU, and the reset leaves the
/// amplifier disabled. Feeding it from anywhere else would defeat that.
#[derive(Debug)]
pub struct Watchdog {
    /// The IWDG registers.
    iwdg: pac::IWDG,
    /// Every reset flag of RCC_CSR before they were cleared.
    reset_causes: hopper_control::boot::ResetCauses,
}

impl Watchdog {
    /// Unlock (0x5555), prescaler 4, reload 39, start (0xCCCC), first feed.
    fn start(iwdg: pac::IWDG, rcc: &pac::RCC) -> Self {
        // The PR/RLR writes reach the watchdog's LSI domain only while the LSI
        // runs; start it first so the new values apply at once, not after the
        // default 512 ms timeout. Bounded: if it never reports ready, the
        // start key below forces it on anyway.
        // Why the MCU last reset: read every reset flag, then clear them
        // (RMVF) so that the next reset reports only its own cause.
        let reset_causes = take_reset_causes(rcc);
        rcc.csr().modify(|_, w| w.lsion().on());
        let _ = wait_for(|| rcc.csr().read().lsirdy().is_ready());

        iwdg.kr().write(|w| w.key().unlock());
        iwdg.pr().write(|w| w.pr().divide_by4());
        iwdg.rlr().write(|w| w.rl().set(IWDG_RELOAD));
        // Up to 5 LSI cycles (~160 µs) each. Bounded: on timeout the watchdog
        // still starts, only with the previous values for a while.
        let _ = wait_for(|| {
            let sr = iwdg.sr().read();
            !sr.pvu().bit_is_set() && !sr.rvu().bit_is_set()
        });
        iwdg.kr().write(|w| w.key().start());
        // Load the 5 ms reload now rather than counting down from 0xFFF.
        iwdg.kr().write(|w| w.key().feed());
        Self { iwdg, reset_causes }
    }

    /// Whether the IWDG caused the reset the firmware is starting from: the
    /// control task stopped, or `hopper_control::watchdog::FeedPolicy`
    /// starved it. The application must then start with a fault latched
    /// (`Supervisor::report_overrun`), so a watchdog reset never restarts
    /// the controller by itself. QEMU models no IWDG (nor RCC): there it
    /// reads `false`.
    pub fn caused_last_reset(&self) -> bool {
        self.reset_causes
            .contains(hopper_control::boot::ResetCause::IndependentWatchdog)
    }

    /// Reloads the counter (key 0xAAAA). Call once per control period, from
    /// the control task only.
    pub fn feed(&mut self) {
        self.iwdg.kr().write(|w| w.key().feed());
    }
}

/// The dump button (to GND, pull-up; PC13 on the H405), debounced by slow polling.
#[derive(Debug)]
pub struct DumpButton {
    /// Its pin.
    pin: pinmap::Dump,
    /// Debounced state: pressed.
    pressed: bool,
    /// The previous raw sample: pressed.
    last_sample: bool,
}

impl DumpButton {
    /// true once per press (edge-detected, debounced by polling at a low rate)
    ///
    /// Poll at 50–100 Hz: the state changes only when two consecutive samples
    /// agree, so contact bounce (< 5 ms) and single-sample glitches (motor
    /// noise) are ignored and a press must last two polls. A button held
    /// through `init` counts only after it has been released.
    pub fn pressed(&mut self) -> bool {
        let sample = embedded_hal::digital::InputPin::is_low(&mut self.pin).unwrap_or(false);
        let agreed = sample == self.last_sample;
        self.last_sample = sample;
        if agreed && sample != self.pressed {
            self.pressed = sample;
            return sample;
        }
        false
    }
}
