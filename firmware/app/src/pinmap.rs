//! The board's pin map: which pin, timer, ADC channel and USART each of the
//! hopper's signals uses, chosen at build time by a cargo feature of
//! `hopper-app`. Everything else in [`crate::board`] (clocks, the
//! converters' and the deadman's logic, the watchdog, the bring-up order)
//! is the same on every board: another board is another module here.
//!
//! | Profile | Feature | Board | Crystal |
//! |---------|---------|-------|---------|
//! | [`h405`] | (default) | Olimex STM32-H405, and any F405 board breaking out the pins below | 8 MHz (`hse-12mhz` for 12 MHz) |
//! | [`feather`] | `feather` | Adafruit Feather STM32F405 Express | 12 MHz (the feature implies `hse-12mhz`) |
//!
//! | Signal | `h405` | `feather` (its header) |
//! |---|---|---|
//! | AMP_EN, the deadman | PB0, TIM3_CH3 (AF2) | PB14, TIM12_CH1 (AF9) (MISO) |
//! | e-stop input | PB1 | PB9 (D10) |
//! | amplifier fault input | PB4 | PC2 (D12) |
//! | dump button | PC13 | PC3 (D11) |
//! | DAC | PA4 | PA4 (A0) |
//! | hip amplifier's DAC (the planar machine) | PA5 (DAC channel 2) | PA5 (A1) |
//! | load cell, potentiometer | PA2, PA3 (ADC IN2, IN3) | PC4, PC5 (IN14, IN15) (A4, A5) |
//! | motor encoder | PA15, PB3 (TIM2, 32-bit, AF1) | PC6, PC7 (TIM8, 16-bit, AF3) (D6, D5) |
//! | height encoder | PA0, PA1 (TIM5, 32-bit, AF2) | PA6, PA7 (TIM3, 16-bit, AF2) (A2, A3) |
//! | hip encoder (the planar machine) | PC6, PC7 (TIM8, 16-bit, AF3) | PB6, PB7 (TIM4, 16-bit, AF2) (SCL, SDA) |
//! | control timer (no pin: its TRGO starts the ADC) | TIM4 | TIM2 |
//! | host link | PA9, PA10 (USART1, AF7, APB2) | PB10, PB11 (USART3, AF7, APB1) (TX, RX) |
//!
//! The hip's amplifier takes its enable from AMP_EN too (both amplifiers'
//! enable inputs on the one deadman output): the hip can no more be
//! enabled without the deadman, the e-stop's hardware break or the fault
//! paths' [`amp_en_low`] than the leg. The Feather's three encoder pin
//! pairs are TIM3's, TIM8's and TIM4's, so its control timer is TIM2 (its
//! TRGO is one of the ADC's injected triggers too).
//!
//! Both maps keep AMP_EN on GPIOB, so the fault paths' stack-free entry
//! (`fault_handlers!`) and [`amp_en_low`] are one piece of code with the
//! pin's number from the map. The 16-bit encoder counters of the Feather
//! are what the calibration's `motor_counter_bits` and
//! `height_counter_bits` allow for (the period unwraps them).

use stm32f4::stm32f405 as pac;

#[cfg(not(feature = "feather"))]
pub use h405::*;

#[cfg(feature = "feather")]
pub use feather::*;

#[cfg(all(feature = "feather", feature = "qemu-sim"))]
compile_error!(
    "the QEMU images run on netduinoplus2's pins (the default map): build them without `feather`"
);

/// One pin of GPIOB or GPIOC (`PORT`), number `N`, as an embedded-hal pin.
/// Zero-sized: its reads are of IDR and its writes one atomic BSRR store,
/// which no other owner of the port can race with.
/// Made only here (`new` is private; the board gets its inputs from
/// [`estop`], [`amp_fault`] and [`dump_button`]), so no other code can
/// drive AMP_EN.
#[derive(Debug)]
pub struct PortPin<const PORT: char, const N: u8>(());

impl<const PORT: char, const N: u8> PortPin<PORT, N> {
    /// The pin; `PORT` must be `'B'` or `'C'` and `N` below 16.
    const fn new() -> Self {
        const {
            assert!(N < 16 && (PORT == 'B' || PORT == 'C'));
        }
        PortPin(())
    }

    /// The port's input data register.
    fn idr() -> u32 {
        #[allow(unsafe_code)] // A read of a port's input register.
        // SAFETY: the fixed addresses of GPIOB's and GPIOC's register
        // blocks; IDR is read-only.
        unsafe {
            match PORT {
                'C' => (*pac::GPIOC::ptr()).idr().read().bits(),
                _ => (*pac::GPIOB::ptr()).idr().read().bits(),
            }
        }
    }
}

impl<const PORT: char, const N: u8> embedded_hal::digital::ErrorType for PortPin<PORT, N> {
    type Error = core::convert::Infallible;
}

impl<const PORT: char, const N: u8> embedded_hal::digital::InputPin for PortPin<PORT, N> {
    fn is_high(&mut self) -> Result<bool, Self::Error> {
        Ok(Self::idr() & (1 << N) != 0)
    }
    fn is_low(&mut self) -> Result<bool, Self::Error> {
        Ok(Self::idr() & (1 << N) == 0)
    }
}

impl<const N: u8> embedded_hal::digital::OutputPin for PortPin<'B', N> {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        #[allow(unsafe_code)] // One atomic store to the port's set/reset register.
        // SAFETY: GPIOB's fixed address; BSRR's write touches only pin N.
        unsafe {
            (*pac::GPIOB::ptr()).bsrr().write(|w| w.bits(1 << (N + 16)));
        }
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        #[allow(unsafe_code)] // One atomic store to the port's set/reset register.
        // SAFETY: GPIOB's fixed address; BSRR's write touches only pin N.
        unsafe {
            (*pac::GPIOB::ptr()).bsrr().write(|w| w.bits(1 << N));
        }
        Ok(())
    }
}

/// The e-stop input.
pub(crate) const fn estop() -> Estop {
    PortPin::new()
}

/// The amplifier-fault input.
pub(crate) const fn amp_fault() -> AmpFault {
    PortPin::new()
}

/// The dump button.
pub(crate) const fn dump_button() -> Dump {
    PortPin::new()
}

/// Whether AMP_EN reads low: its input register follows the pin in its
/// alternate function too (the deadman's readback).
pub(crate) fn amp_en_reads_low() -> bool {
    PortPin::<'B', { AMP_EN }>::idr() & (1 << AMP_EN) == 0
}

/// Moves the map's encoder counters and its control timer out of the
/// device peripherals: `(motor, height, hip, control timer)`, of the
/// types [`MotorCounter`], [`HeightCounter`], [`HipCounter`] and
/// [`ControlTimer`] (the board's `init` names them). A macro: the fields moved depend on the map, and a function
/// cannot move fields out of its caller's `Peripherals`.
#[cfg(not(feature = "feather"))]
#[macro_export]
macro_rules! take_counters {
    ($dp:ident) => {
        ($dp.TIM2, $dp.TIM5, $dp.TIM8, $dp.TIM4)
    };
}
/// The same on the Feather's map.
#[cfg(feature = "feather")]
#[macro_export]
macro_rules! take_counters {
    ($dp:ident) => {
        ($dp.TIM8, $dp.TIM3, $dp.TIM4, $dp.TIM2)
    };
}
pub use take_counters;

/// Moves the map's deadman timer and link USART out of the device
/// peripherals: `(deadman, link)`.
#[cfg(not(feature = "feather"))]
#[macro_export]
macro_rules! take_deadman_and_link {
    ($dp:ident) => {
        ($dp.TIM3, $dp.USART1)
    };
}
/// The same on the Feather's map.
#[cfg(feature = "feather")]
#[macro_export]
macro_rules! take_deadman_and_link {
    ($dp:ident) => {
        ($dp.TIM12, $dp.USART3)
    };
}
pub use take_deadman_and_link;

/// The BSRR word that drives AMP_EN low (its reset bit): one atomic store.
pub const AMP_EN_BSRR_RESET: u32 = 1 << (16 + AMP_EN as u32);
/// AMP_EN's two MODER bits.
pub const AMP_EN_MODER_MASK: u32 = 0b11 << (2 * AMP_EN as u32);
/// AMP_EN's MODER bits for a general-purpose output (0b01).
pub const AMP_EN_MODER_OUTPUT: u32 = 0b01 << (2 * AMP_EN as u32);
/// The deadman channel's OCxM field in its CCMR (bits 6:4 for channel 1
/// and channel 3 alike), for the HardFault entry's writes.
pub const DEADMAN_OCM_MASK: u32 = 0b111 << 4;
/// OCxM = 0b100, forced inactive.
pub const DEADMAN_OCM_FORCE_INACTIVE: u32 = 0b100 << 4;

/// AMP_EN low, then an output, its port clocked (GPIOA-C): the output is
/// latched low *before* the pin becomes an output, so it never drives
/// high, not even for one cycle. Every image's `init` does this first.
pub fn amp_en_low(rcc: &pac::RCC, gpiob: &pac::GPIOB) {
    rcc.ahb1enr().modify(|_, w| {
        w.gpioaen()
            .enabled()
            .gpioben()
            .enabled()
            .gpiocen()
            .enabled()
    });
    // Read back: errata ES0182 "delay after an RCC peripheral clock enabling".
    let _ = rcc.ahb1enr().read();
    gpiob.bsrr().write(|w| w.br(AMP_EN).set_bit());
    gpiob.otyper().modify(|_, w| w.ot(AMP_EN).push_pull());
    gpiob.ospeedr().modify(|_, w| w.ospeedr(AMP_EN).low_speed());
    gpiob.pupdr().modify(|_, w| w.pupdr(AMP_EN).floating());
    gpiob.moder().modify(|_, w| w.moder(AMP_EN).output());
}

/// The debugger's freeze of both maps' deadman timers (TIM3, TIM12) off
/// (DBGMCU_APB1_FZ): a debugger may have set it in an earlier session, and
/// only a power-on reset clears it; frozen, a halted core would hold the
/// enable high.
pub fn unfreeze_timers(dbgmcu: &pac::DBGMCU) {
    dbgmcu
        .apb1_fz()
        .modify(|_, w| w.dbg_tim3_stop().clear_bit().dbg_tim12_stop().clear_bit());
}

/// The deadman timer's registers, for [`hopper_control::deadman`]'s one
/// sequence of writes (`TimerRegs`: one method, one register write),
/// written once per timer type (TIM3's channel 3 on the H405, TIM12's
/// channel 1 on the Feather).
#[derive(Debug)]
pub struct DeadmanRegs(pub DeadmanTimer);

impl DeadmanRegs {
    /// The registers from any context (the panic and fault paths, which
    /// own no peripheral).
    ///
    /// # Safety
    /// Only where nothing else can write the timer meanwhile: a path that
    /// does not return (the other owner never runs again).
    #[allow(unsafe_code)] // A second handle on the timer, for a path that does not return.
    pub unsafe fn steal() -> Self {
        // SAFETY: the caller's.
        DeadmanRegs(unsafe { DeadmanTimer::steal() })
    }
}

/// The deadman on a timer type: its channel's register and field names.
macro_rules! deadman_regs {
    ($ccmr:ident, $ocm:ident, $ocpe:ident, $ccs:ident, $ccr:ident, $cce:ident, $ccp:ident) => {
        impl hopper_control::deadman::TimerRegs for DeadmanRegs {
            fn write_cr1(&mut self, opm: bool, cen: bool) {
                self.0.cr1().write(|w| w.opm().bit(opm).cen().bit(cen));
            }
            fn counter_enabled(&self) -> bool {
                self.0.cr1().read().cen().is_enabled()
            }
            fn write_psc(&mut self, psc: u16) {
                self.0.psc().write(|w| w.psc().set(psc));
            }
            fn write_arr(&mut self, arr: u16) {
                self.0.arr().write(|w| w.arr().set(arr));
            }
            fn write_ccr(&mut self, ccr: u16) {
                self.0.$ccr().write(|w| w.ccr().set(ccr));
            }
            fn write_ocm(&mut self, mode: hopper_control::deadman::OcMode) {
                use hopper_control::deadman::OcMode;
                self.0.$ccmr().modify(|_, w| {
                    let w = w.$ccs().output().$ocpe().disabled();
                    match mode {
                        OcMode::ForceInactive => w.$ocm().force_inactive(),
                        OcMode::Pwm2 => w.$ocm().pwm_mode2(),
                    }
                });
            }
            fn generate_update(&mut self) {
                self.0.egr().write(|w| w.ug().set_bit());
            }
            fn clear_update_flag(&mut self) {
                self.0.sr().write(|w| w.uif().clear_bit());
            }
            fn write_cnt(&mut self, cnt: u16) {
                self.0.cnt().write(|w| w.cnt().set(cnt));
            }
            fn enable_output(&mut self) {
                self.0
                    .ccer()
                    .write(|w| w.$ccp().clear_bit().$cce().set_bit());
            }
            fn pin_reads_low(&self) -> Option<bool> {
                Some(amp_en_reads_low())
            }
        }
    };
}

#[cfg(not(feature = "feather"))]
deadman_regs!(ccmr2_output, oc3m, oc3pe, cc3s, ccr3, cc3e, cc3p);
#[cfg(feature = "feather")]
deadman_regs!(ccmr1_output, oc1m, oc1pe, cc1s, ccr1, cc1e, cc1p);

/// Encoder mode 3 (×4) on CH1/CH2, filtered, wrapping at the counter's
/// width (`$max`), counter at 0 and running. A macro because the
/// encoder timers are different PAC types with the same registers.
///
/// An encoder's two inputs on pins 6 and 7 of a port: pulled up, in
/// alternate function `$af` (written before the mode, so neither pin sits
/// in another function). A macro: the ports are different register blocks.
macro_rules! encoder_pins_6_7 {
    ($port:expr, $af:ident) => {{
        let port = $port;
        port.pupdr()
            .modify(|_, w| w.pupdr6().pull_up().pupdr7().pull_up());
        port.afrl().modify(|_, w| w.afrl6().$af().afrl7().$af());
        port.moder()
            .modify(|_, w| w.moder6().alternate().moder7().alternate());
    }};
}

/// Filter f_DTS/2, N = 8: an edge must be stable 8 samples at 42 MHz (190 ns;
/// 1 µs on the HSI fallback; 95 ns on the Feather's TIM8, an APB2 timer) to
/// count. The motor encoder's fastest edges (500 lines ×4 at 10 000 rpm)
/// are 3 µs apart.
macro_rules! configure_encoder {
    ($tim:expr, $max:expr) => {{
        let tim = &$tim;
        tim.cr1().modify(|_, w| w.cen().disabled());
        tim.smcr().modify(|_, w| w.sms().disabled());
        tim.ccmr1_input().write(|w| {
            w.cc1s()
                .ti1()
                .ic1f()
                .fdts_div2_n8()
                .ic1psc()
                .no_prescaler()
                .cc2s()
                .ti2()
                .ic2f()
                .fdts_div2_n8()
                .ic2psc()
                .no_prescaler()
        });
        // Non-inverted inputs: CCxP = CCxNP = 0 (both edges are counted by
        // the encoder mode itself).
        tim.ccer().write(|w| {
            w.cc1p()
                .rising_edge()
                .cc1np()
                .clear_bit()
                .cc2p()
                .rising_edge()
                .cc2np()
                .clear_bit()
        });
        tim.arr().write(|w| w.arr().set($max));
        tim.cnt().write(|w| w.cnt().set(0));
        tim.smcr().modify(|_, w| w.sms().encoder_mode_3());
        tim.cr1().modify(|_, w| w.ckd().div1().cen().enabled());
    }};
}

/// The bus clock a USART runs from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bus {
    /// APB1 (USART2, USART3).
    Apb1,
    /// APB2 (USART1, USART6).
    Apb2,
}

/// The Olimex STM32-H405's map (docs/board.md, "Wiring"): every signal on
/// a pin the H405 breaks out, both encoders on 32-bit timers.
#[cfg_attr(feature = "feather", allow(dead_code))]
pub mod h405 {
    use super::PortPin;
    use super::{pac, Bus};

    /// The profile's name, for the logs.
    pub const NAME: &str = "h405";
    /// AMP_EN's pin number on GPIOB (PB0).
    pub const AMP_EN: u8 = 0;
    /// The deadman's timer: TIM3, its channel 3 on PB0 (AF2).
    pub type DeadmanTimer = pac::TIM3;
    /// TIM3's register block address (RM0090, memory map).
    pub const DEADMAN_TIMER_ADDR: u32 = 0x4000_0400;
    /// The offset of the deadman channel's mode register: TIM3_CCMR2
    /// (OC3M in bits 6:4).
    pub const DEADMAN_CCMR_OFFSET: u32 = 0x1C;
    /// The e-stop input, PB1.
    pub type Estop = PortPin<'B', 1>;
    /// The amplifier-fault input, PB4.
    pub type AmpFault = PortPin<'B', 4>;
    /// The dump button, PC13.
    pub type Dump = PortPin<'C', 13>;
    /// The motor encoder's counter: TIM2 (32-bit).
    pub type MotorCounter = pac::TIM2;
    /// The height encoder's counter: TIM5 (32-bit).
    pub type HeightCounter = pac::TIM5;
    /// The hip encoder's counter: TIM8 (16-bit, an APB2 timer), PC6, PC7.
    pub type HipCounter = pac::TIM8;
    /// The control timer: TIM4 (its update is its TRGO, the ADC's trigger).
    pub type ControlTimer = pac::TIM4;
    /// Width of the motor's and the height's encoder counters in bits
    /// (the hip's, TIM8, is 16-bit).
    pub const ENCODER_COUNTER_BITS: u8 = 32;
    /// ADC channel of the load cell (PA2).
    pub const LOADCELL_CHANNEL: u8 = 2;
    /// ADC channel of the leg potentiometer (PA3).
    pub const POT_CHANNEL: u8 = 3;
    /// The host link's USART.
    pub type LinkUsart = pac::USART1;
    /// Its interrupt.
    pub const LINK_INTERRUPT: pac::Interrupt = pac::Interrupt::USART1;
    /// Its name, for the logs.
    pub const LINK_NAME: &str = "USART1";
    /// Its bus.
    pub const LINK_BUS: Bus = Bus::Apb2;

    /// E-stop (PB1), amplifier fault (PB4) and dump button (PC13): inputs
    /// with pull-ups.
    pub fn configure_inputs(gpiob: &pac::GPIOB, gpioc: &pac::GPIOC) {
        gpiob
            .pupdr()
            .modify(|_, w| w.pupdr1().pull_up().pupdr4().pull_up());
        gpiob
            .moder()
            .modify(|_, w| w.moder1().input().moder4().input());
        gpioc.pupdr().modify(|_, w| w.pupdr13().pull_up());
        gpioc.moder().modify(|_, w| w.moder13().input());
    }

    /// ADC inputs (PA2, PA3) analog; encoder inputs (PA0, PA1, PA15, PB3,
    /// and the hip's PC6, PC7) in their alternate functions with pull-ups.
    /// The AF number is written before the mode, so a pin never sits in
    /// the wrong alternate function.
    pub fn configure_analog_and_encoder_pins(
        gpioa: &pac::GPIOA,
        gpiob: &pac::GPIOB,
        gpioc: &pac::GPIOC,
    ) {
        gpioa.pupdr().modify(|_, w| {
            w.pupdr2()
                .floating()
                .pupdr3()
                .floating()
                .pupdr0()
                .pull_up()
                .pupdr1()
                .pull_up()
                .pupdr15()
                .pull_up()
        });
        gpioa
            .moder()
            .modify(|_, w| w.moder2().analog().moder3().analog());
        gpioa.afrl().modify(|_, w| w.afrl0().af2().afrl1().af2());
        gpioa.afrh().modify(|_, w| w.afrh15().af1());
        gpioa.moder().modify(|_, w| {
            w.moder0()
                .alternate()
                .moder1()
                .alternate()
                .moder15()
                .alternate()
        });
        gpiob.pupdr().modify(|_, w| w.pupdr3().pull_up());
        gpiob.afrl().modify(|_, w| w.afrl3().af1());
        gpiob.moder().modify(|_, w| w.moder3().alternate());
        // The hip encoder: PC6, PC7 (TIM8, AF3).
        encoder_pins_6_7!(gpioc, af3);
    }

    /// The clocks of the encoders' timers (TIM2, TIM5, the hip's TIM8),
    /// the deadman's (TIM3), the control timer (TIM4) and ADC1.
    pub fn enable_clocks(rcc: &pac::RCC) {
        rcc.apb1enr().modify(|_, w| {
            w.tim2en()
                .enabled()
                .tim3en()
                .enabled()
                .tim4en()
                .enabled()
                .tim5en()
                .enabled()
        });
        rcc.apb2enr()
            .modify(|_, w| w.adc1en().enabled().tim8en().enabled());
        let _ = rcc.apb2enr().read();
    }

    /// The deadman's timer (TIM3) and TIM5 (the HIL image's counter).
    pub fn enable_hil_clocks(rcc: &pac::RCC) {
        rcc.apb1enr()
            .modify(|_, w| w.tim3en().enabled().tim5en().enabled());
        let _ = rcc.apb1enr().read();
    }

    /// Both encoders counting, wrapping at 32 bits, and the hip's at 16.
    pub fn configure_encoders(motor: &MotorCounter, height: &HeightCounter, hip: &HipCounter) {
        configure_encoder!(motor, u32::MAX);
        configure_encoder!(height, u32::MAX);
        configure_encoder!(hip, u16::MAX);
    }

    /// ADC1's injected group started by the control timer's TRGO.
    pub fn adc_trigger(w: &mut pac::adc1::cr2::W) -> &mut pac::adc1::cr2::W {
        w.jextsel().tim4trgo()
    }

    /// 56-cycle sample time on both converter channels.
    pub fn set_sample_times(adc: &pac::ADC1) {
        adc.smpr2()
            .modify(|_, w| w.smp2().cycles56().smp3().cycles56());
    }

    /// PB0 from its GPIO output (driven low) to TIM3_CH3 (AF2), the AF
    /// number before the mode.
    pub fn amp_en_to_deadman(gpiob: &pac::GPIOB) {
        gpiob.afrl().modify(|_, w| w.afrl0().af2());
        gpiob.moder().modify(|_, w| w.moder0().alternate());
    }

    /// USART1 clocked, PA9 (TX) and PA10 (RX, pulled up) in AF7.
    pub fn configure_link(rcc: &pac::RCC, gpioa: &pac::GPIOA, _gpiob: &pac::GPIOB) {
        rcc.apb2enr().modify(|_, w| w.usart1en().enabled());
        let _ = rcc.apb2enr().read();
        gpioa.afrh().modify(|_, w| w.afrh9().af7().afrh10().af7());
        gpioa.pupdr().modify(|_, w| w.pupdr10().pull_up());
        gpioa
            .moder()
            .modify(|_, w| w.moder9().alternate().moder10().alternate());
    }
}

/// The Adafruit Feather STM32F405 Express's map (its pins as MicroPython's
/// `ADAFRUIT_F405_EXPRESS/pins.csv` lists them): every signal on a header
/// pin. The Feather breaks out none of PB0, PB1, PA0-PA2 and PB4; PA3 is
/// its battery monitor, PA9 and PA10 its USB, PA15, PB3 and PB4 its SPI
/// flash. Its encoders count on 16-bit timers.
#[cfg_attr(not(feature = "feather"), allow(dead_code))]
pub mod feather {
    use super::PortPin;
    use super::{pac, Bus};

    /// The profile's name, for the logs.
    pub const NAME: &str = "feather";
    /// AMP_EN's pin number on GPIOB (PB14, the MISO header pin).
    pub const AMP_EN: u8 = 14;
    /// The deadman's timer: TIM12 (one-pulse capable, as TIM9), its
    /// channel 1 on PB14 (AF9).
    pub type DeadmanTimer = pac::TIM12;
    /// TIM12's register block address (RM0090, memory map).
    pub const DEADMAN_TIMER_ADDR: u32 = 0x4000_1800;
    /// The offset of the deadman channel's mode register: TIM12_CCMR1
    /// (OC1M in bits 6:4).
    pub const DEADMAN_CCMR_OFFSET: u32 = 0x18;
    /// The e-stop input, PB9 (D10).
    pub type Estop = PortPin<'B', 9>;
    /// The amplifier-fault input, PC2 (D12).
    pub type AmpFault = PortPin<'C', 2>;
    /// The dump button, PC3 (D11).
    pub type Dump = PortPin<'C', 3>;
    /// The motor encoder's counter: TIM8 (16-bit, an APB2 timer).
    pub type MotorCounter = pac::TIM8;
    /// The height encoder's counter: TIM3 (16-bit).
    pub type HeightCounter = pac::TIM3;
    /// The hip encoder's counter: TIM4 (16-bit), PB6, PB7 (SCL, SDA).
    pub type HipCounter = pac::TIM4;
    /// The control timer: TIM2 (TIM4's pins count the hip).
    pub type ControlTimer = pac::TIM2;
    /// Width of every encoder counter in bits.
    pub const ENCODER_COUNTER_BITS: u8 = 16;
    /// ADC channel of the load cell (PC4, A4).
    pub const LOADCELL_CHANNEL: u8 = 14;
    /// ADC channel of the leg potentiometer (PC5, A5).
    pub const POT_CHANNEL: u8 = 15;
    /// The host link's USART.
    pub type LinkUsart = pac::USART3;
    /// Its interrupt.
    pub const LINK_INTERRUPT: pac::Interrupt = pac::Interrupt::USART3;
    /// Its name, for the logs.
    pub const LINK_NAME: &str = "USART3";
    /// Its bus.
    pub const LINK_BUS: Bus = Bus::Apb1;

    /// E-stop (PB9), amplifier fault (PC2) and dump button (PC3): inputs
    /// with pull-ups.
    pub fn configure_inputs(gpiob: &pac::GPIOB, gpioc: &pac::GPIOC) {
        gpiob.pupdr().modify(|_, w| w.pupdr9().pull_up());
        gpiob.moder().modify(|_, w| w.moder9().input());
        gpioc
            .pupdr()
            .modify(|_, w| w.pupdr2().pull_up().pupdr3().pull_up());
        gpioc
            .moder()
            .modify(|_, w| w.moder2().input().moder3().input());
    }

    /// ADC inputs (PC4, PC5) analog; encoder inputs (PC6, PC7 AF3 for
    /// TIM8; PA6, PA7 AF2 for TIM3; the hip's PB6, PB7 AF2 for TIM4) in
    /// their alternate functions with pull-ups, the AF number before the
    /// mode.
    pub fn configure_analog_and_encoder_pins(
        gpioa: &pac::GPIOA,
        gpiob: &pac::GPIOB,
        gpioc: &pac::GPIOC,
    ) {
        gpioc
            .pupdr()
            .modify(|_, w| w.pupdr4().floating().pupdr5().floating());
        gpioc
            .moder()
            .modify(|_, w| w.moder4().analog().moder5().analog());
        encoder_pins_6_7!(gpioc, af3);
        encoder_pins_6_7!(gpioa, af2);
        encoder_pins_6_7!(gpiob, af2);
    }

    /// The clocks of the encoders' timers (TIM8 on APB2, TIM3, the hip's
    /// TIM4), the deadman's (TIM12), the control timer (TIM2) and ADC1.
    pub fn enable_clocks(rcc: &pac::RCC) {
        rcc.apb1enr().modify(|_, w| {
            w.tim2en()
                .enabled()
                .tim3en()
                .enabled()
                .tim4en()
                .enabled()
                .tim12en()
                .enabled()
        });
        rcc.apb2enr()
            .modify(|_, w| w.adc1en().enabled().tim8en().enabled());
        let _ = rcc.apb2enr().read();
    }

    /// The deadman's timer (TIM12) and TIM5 (the HIL image's counter).
    pub fn enable_hil_clocks(rcc: &pac::RCC) {
        rcc.apb1enr()
            .modify(|_, w| w.tim12en().enabled().tim5en().enabled());
        let _ = rcc.apb1enr().read();
    }

    /// The three encoders counting, wrapping at 16 bits.
    pub fn configure_encoders(motor: &MotorCounter, height: &HeightCounter, hip: &HipCounter) {
        configure_encoder!(motor, u16::MAX);
        configure_encoder!(height, u16::MAX);
        configure_encoder!(hip, u16::MAX);
    }

    /// ADC1's injected group started by the control timer's TRGO.
    pub fn adc_trigger(w: &mut pac::adc1::cr2::W) -> &mut pac::adc1::cr2::W {
        w.jextsel().tim2trgo()
    }

    /// 56-cycle sample time on both converter channels.
    pub fn set_sample_times(adc: &pac::ADC1) {
        adc.smpr1()
            .modify(|_, w| w.smp14().cycles56().smp15().cycles56());
    }

    /// PB14 from its GPIO output (driven low) to TIM12_CH1 (AF9), the AF
    /// number before the mode.
    pub fn amp_en_to_deadman(gpiob: &pac::GPIOB) {
        gpiob.afrh().modify(|_, w| w.afrh14().af9());
        gpiob.moder().modify(|_, w| w.moder14().alternate());
    }

    /// USART3 clocked, PB10 (TX) and PB11 (RX, pulled up) in AF7.
    pub fn configure_link(rcc: &pac::RCC, _gpioa: &pac::GPIOA, gpiob: &pac::GPIOB) {
        rcc.apb1enr().modify(|_, w| w.usart3en().enabled());
        let _ = rcc.apb1enr().read();
        gpiob.afrh().modify(|_, w| w.afrh10().af7().afrh11().af7());
        gpiob.pupdr().modify(|_, w| w.pupdr11().pull_up());
        gpiob
            .moder()
            .modify(|_, w| w.moder10().alternate().moder11().alternate());
    }
}
