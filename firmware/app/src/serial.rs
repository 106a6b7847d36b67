//! The host link's transport on the pin map's USART (USART1 on PA9 TX,
//! PA10 RX by default; `crate::pinmap`), for the board and the QEMU image
//! alike: 8N1 at [`LINK_BAUD`].
//!
//! The bytes go through two lock-free single-producer queues, so neither
//! side ever waits for the other:
//!
//! - receive: the USART's interrupt moves each received byte into
//!   [`RxQueue`]. It runs at priority 4, *above* the control task: the USART
//!   has no receive FIFO, and at 921,600 baud a byte must be read within
//!   10.85 us, less than the control task's period. Its handler is a few
//!   dozen cycles and shares nothing but the lock-free queues (its cost,
//!   about 18 bytes a period at full duplex, is in the control interrupt's
//!   budget in docs/link.md). The link task (priority 2) drains the queue
//!   once per period into `hopper_robot_link::Endpoint::service`. A full
//!   queue drops the byte (the frame then fails its CRC and is counted).
//! - transmit: the link task frames its messages into [`TxQueue`]
//!   through [`LinkTx`] (a frame goes in whole or not at all) and pends the
//!   interrupt, which feeds the data register while it is empty and turns
//!   its TXE interrupt off when the queue runs dry.
//!
//! QEMU's netduinoplus2 models USART1 (wired to the first `-serial`), not
//! its baud rate: there the bytes move as fast as the host socket takes
//! them.

use hopper_robot_link::Tx;
use spsc::spsc::{Consumer, Producer, Queue};
use stm32f4::stm32f405 as pac;

/// The link's baud rate: 921,600 carries 92,160 bytes/s, 1 kHz of full
/// telemetry records (at most 40 bytes framed) with room to spare.
pub const LINK_BAUD: u32 = 921_600;

/// Received bytes waiting for the control task: 512 bytes, 5.6 ms of the
/// line at full rate, more than 50 periods.
pub type RxQueue = Queue<u8, RX_BYTES>;
/// [`RxQueue`]'s length.
pub const RX_BYTES: usize = 512;
/// The serial interrupt's end of [`RxQueue`].
pub type RxIn<'a> = Producer<'a, u8, RX_BYTES>;
/// The link task's end of [`RxQueue`].
pub type RxOut<'a> = Consumer<'a, u8, RX_BYTES>;

/// Bytes waiting for the line: 4 KiB, 44 ms at 921,600 baud.
pub type TxQueue = Queue<u8, TX_BYTES>;
/// [`TxQueue`]'s length.
pub const TX_BYTES: usize = 4096;
/// The link task's end of [`TxQueue`].
pub type TxIn<'a> = Producer<'a, u8, TX_BYTES>;
/// The serial interrupt's end of [`TxQueue`].
pub type TxOut<'a> = Consumer<'a, u8, TX_BYTES>;

/// The link task's end of the transmit queue.
pub struct LinkTx<'a> {
    tx: TxIn<'a>,
}

impl<'a> LinkTx<'a> {
    /// Wraps the producer.
    pub fn new(tx: TxIn<'a>) -> Self {
        Self { tx }
    }
}

impl Tx for LinkTx<'_> {
    fn room(&self) -> usize {
        self.tx.capacity().saturating_sub(self.tx.len())
    }

    fn put(&mut self, frame: &[u8]) {
        for &b in frame {
            // Cannot fail: the endpoint checked the room first, and only
            // this end adds to the queue.
            let _ = self.tx.enqueue(b);
        }
        // Start the transmitter (the interrupt stops itself when done).
        cortex_m::peripheral::NVIC::pend(crate::pinmap::LINK_INTERRUPT);
    }
}

/// The interrupt's side: the USART and the queues' other ends.
pub struct Serial<'a> {
    usart: crate::pinmap::LinkUsart,
    rx: RxIn<'a>,
    tx: TxOut<'a>,
    /// What the line lost, by cause.
    counts: hopper_robot_link::SerialCounts,
}

/// The USART divider for `baud` from its bus clock `bus_hz` (16x
/// oversampling), rounded to the nearest sixteenth.
pub const fn brr(bus_hz: u32, baud: u32) -> u32 {
    (bus_hz + baud / 2) / baud
}

impl<'a> Serial<'a> {
    /// Configures the pin map's link pins and USART at [`LINK_BAUD`] from
    /// `bus_hz` (its bus clock), the receive interrupt on. The GPIO ports
    /// must be clocked.
    pub fn new(
        usart: crate::pinmap::LinkUsart,
        rcc: &pac::RCC,
        gpioa: &pac::GPIOA,
        gpiob: &pac::GPIOB,
        bus_hz: u32,
        rx: RxIn<'a>,
        tx: TxOut<'a>,
    ) -> Self {
        crate::pinmap::configure_link(rcc, gpioa, gpiob);
        usart.brr().write(|w| brr_bits(w, brr(bus_hz, LINK_BAUD)));
        usart.cr1().write(|w| {
            w.ue()
                .enabled()
                .te()
                .enabled()
                .re()
                .enabled()
                .rxneie()
                .enabled()
        });
        Self {
            usart,
            rx,
            tx,
            counts: hopper_robot_link::SerialCounts::default(),
        }
    }

    /// Received bytes dropped so far (overruns and a full queue).
    pub fn lost(&self) -> u32 {
        self.counts.overrun.saturating_add(self.counts.full)
    }

    /// What the line lost so far, by cause.
    pub fn counts(&self) -> hopper_robot_link::SerialCounts {
        self.counts
    }

    /// The interrupt: received bytes into the receive queue, queued bytes
    /// to the line while it takes them.
    pub fn on_interrupt(&mut self) {
        let sr = self.usart.sr().read();
        if sr.rxne().bit_is_set() || sr.ore().bit_is_set() {
            // Reading DR clears RXNE (and, after the SR read, an overrun).
            // On an overrun DR still holds the last good byte (RM0090): keep
            // it; the byte after it is the one lost.
            let b = (self.usart.dr().read().bits() & 0xFF) as u8;
            let c = &mut self.counts;
            let count = |n: &mut u32, on: bool| *n = n.saturating_add(u32::from(on));
            count(&mut c.overrun, sr.ore().bit_is_set());
            // A framing error or noise: the byte is kept (the frame's CRC
            // drops the frame), and counted.
            count(&mut c.framing, sr.fe().bit_is_set());
            count(&mut c.noise, sr.nf().bit_is_set());
            count(&mut c.full, self.rx.enqueue(b).is_err());
        }
        while self.usart.sr().read().txe().bit_is_set() {
            match self.tx.dequeue() {
                Some(b) => {
                    self.usart.dr().write(|w| w.dr().set(u16::from(b)));
                }
                None => {
                    self.usart.cr1().modify(|_, w| w.txeie().disabled());
                    return;
                }
            }
        }
        self.usart.cr1().modify(|_, w| w.txeie().enabled());
    }
}

/// BRR's mantissa and fraction as one value (the register's 16 bits).
fn brr_bits(w: &mut pac::usart1::brr::W, v: u32) -> &mut pac::usart1::brr::W {
    w.div_mantissa()
        .set(((v >> 4) & 0x0FFF) as u16)
        .div_fraction()
        .set((v & 0xF) as u8)
}
