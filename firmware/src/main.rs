//! STM32G474 (NUCLEO-G474RE) firmware for the sensorless IFOC drive of the `acim` crate.
//!
//! `main` sets the clocks (170 MHz, boost mode), the watchdog, the UART command channel
//! and either the power-stage path (TIM1 PWM, ADC injected conversions, offset
//! calibration) or, with the `selftest` feature, the motor model on a 5 kHz TIM6
//! interrupt; then it hands the drive to the control interrupt (module `control_isr`) and loops:
//! watchdog, commands, replies, telemetry. See firmware/README.md.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

// Built for the host (`cargo build --workspace`), the firmware is a stub that says how to
// build it: everything below is for the MCU only (`target_os = "none"`), and so are its
// dependencies (Cargo.toml).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "acim-firmware is STM32G474 (Cortex-M4F) firmware; this host build is a stub.\n  \
         build it: cargo build --profile firmware -p acim-firmware --target thumbv7em-none-eabihf\n  \
         host tests of its hardware-independent logic: cargo test -p acim-firmware-core"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod ccm;
#[cfg(target_os = "none")]
mod control_isr;
#[cfg(target_os = "none")]
#[cfg(not(feature = "soft-sincos"))]
mod cordic;
#[cfg(target_os = "none")]
mod flash;
#[cfg(target_os = "none")]
#[cfg_attr(feature = "selftest", allow(dead_code))]
mod hw;
#[cfg(target_os = "none")]
mod rtt;

#[cfg(target_os = "none")]
use {
    acim::math::RAD_S_TO_RPM,
    acim::Drive,
    acim_firmware_core::board::{self, POWER_STAGE},
    acim_firmware_core::control::{self, CommandReply, ControlCommand, ControlLoop},
    acim_firmware_core::convert::Converter,
    acim_firmware_core::dispatch::{self, Dispatch, Platform, Rebuild, Reply, Sent},
    acim_firmware_core::protocol::{self, RequestAssembler},
    acim_firmware_core::settings::{self, Settings},
    acim_firmware_core::store,
    acim_firmware_core::telemetry::{self, TelemetrySample},
    control_isr::{IsrState, CMD_Q, TEL_Q},
    core::sync::atomic::Ordering,
    cortex_m_rt::{entry, exception, ExceptionFrame},
    heapless::spsc::Queue,
    heapless::Deque,
    stm32g4xx_hal::hal_02::serial::{Read as _, Write as _},
    stm32g4xx_hal::independent_watchdog::IndependentWatchdog,
    stm32g4xx_hal::prelude::*,
    stm32g4xx_hal::pwr::{PwrExt, VoltageScale},
    stm32g4xx_hal::rcc::{Config, PllConfig, PllMDiv, PllNMul, PllRDiv, PllSrc, RccExt},
    stm32g4xx_hal::serial::FullConfig,
    stm32g4xx_hal::{pac, time::ExtU32},
};

#[cfg(target_os = "none")]
/// Which sin/cos the drive uses, and how it is made.
mod board_cfg {
    #[cfg(not(feature = "soft-sincos"))]
    pub type Sc = crate::cordic::CordicSinCos;
    #[cfg(feature = "soft-sincos")]
    pub type Sc = acim::frames::FastSinCos;

    #[cfg(not(feature = "soft-sincos"))]
    pub fn sincos(c: stm32g4xx_hal::pac::CORDIC, rcc: &mut stm32g4xx_hal::rcc::Rcc) -> Sc {
        crate::cordic::CordicSinCos::new(c, rcc)
    }
    #[cfg(feature = "soft-sincos")]
    pub fn sincos(_c: stm32g4xx_hal::pac::CORDIC, _rcc: &mut stm32g4xx_hal::rcc::Rcc) -> Sc {
        acim::frames::FastSinCos
    }

    /// Another handle on the sin/cos for a drive rebuilt from new settings (the old drive,
    /// and its handle, are dropped when the new one is swapped in).
    #[cfg(not(feature = "soft-sincos"))]
    pub fn another(rcc: &mut stm32g4xx_hal::rcc::Rcc) -> Sc {
        // SAFETY: the HAL's CORDIC handle is zero-sized; `new` sets the clock enable and
        // CSR to the values `sincos` already set (same configuration), and the control
        // interrupt's operations (write WDATA, read RDATA) are not split by it: the main
        // loop never preempts the interrupt.
        crate::cordic::CordicSinCos::new(unsafe { stm32g4xx_hal::pac::CORDIC::steal() }, rcc)
    }
    #[cfg(feature = "soft-sincos")]
    pub fn another(_rcc: &mut stm32g4xx_hal::rcc::Rcc) -> Sc {
        acim::frames::FastSinCos
    }
}

#[cfg(target_os = "none")]
static mut TEL_QUEUE: Queue<TelemetrySample, TEL_Q> = Queue::new();
#[cfg(target_os = "none")]
static mut CMD_QUEUE: Queue<ControlCommand, CMD_Q> = Queue::new();
#[cfg(target_os = "none")]
static mut REPLY_QUEUE: Queue<CommandReply, CMD_Q> = Queue::new();

#[cfg(all(target_os = "none", not(feature = "selftest")))]
/// The HAL's pin types above are fixed per build: the selected profile must use them.
const _: () = {
    use acim_firmware_core::profile::{pa, pb, pc, GateDrive};
    let b = &board::BOARD;
    if cfg!(feature = "x-nucleo-ihm16m1") {
        assert!(b.fault.pin.is(pb(12)) && b.senses_on([pa(0), pa(1), pb(0), pb(1)]));
        assert!(!b.gates.complementary());
    } else {
        assert!(b.fault.pin.is(pa(6)) && b.senses_on([pa(0), pa(1), pc(0), pc(1)]));
        match b.gates.drive {
            GateDrive::Complementary { low_side, .. } => {
                assert!(low_side[0].is(pa(7)) && low_side[1].is(pb(0)) && low_side[2].is(pb(1)))
            }
            GateDrive::InputEnable { .. } => panic!("input/enable drive: only the IHM16M1 set-up"),
        }
    }
    assert!(
        b.fault.active_low,
        "the break is set up active low with a pull-up"
    );
};

#[cfg(target_os = "none")]
/// The board's name in the `version` reply: `acim-firmware <MODE>`.
const BOARD_NAME: &str = if cfg!(feature = "selftest") {
    "acim-firmware self-test (motor model, outputs disabled)"
} else {
    "acim-firmware power stage"
};

#[cfg(target_os = "none")]
const MODE: &str = BOARD_NAME.split_at("acim-firmware ".len()).1;

#[cfg(target_os = "none")]
#[entry]
fn main() -> ! {
    // first: the control step's code must be in CCM before anything calls it
    ccm::init();

    let Some(dp) = pac::Peripherals::take() else {
        panic!("peripherals taken twice")
    };
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        panic!("core peripherals taken twice")
    };

    // debug halts stop TIM1 and the watchdog; lockup/ECC/parity/PVD break TIM1 in hardware
    hw::freeze_on_debug_halt();
    hw::link_system_break();
    // a stack overflow faults (outputs off) instead of corrupting the statics (review D16)
    hw::stack_guard(&mut cp.MPU, &mut cp.SCB);

    // 170 MHz from HSI16: 16 / 4 * 85 / 2; Range 1 boost mode (needed above 150 MHz);
    // the HAL sets the flash wait states (4 at 170 MHz) during the switch. The HAL does not
    // enable PWR's bus clock, without which its boost-mode write is dropped (review D2).
    dp.RCC.apb1enr1().modify(|_, w| w.pwren().set_bit());
    let _ = dp.RCC.apb1enr1().read(); // the enable takes effect before PWR is accessed
    let pwr = dp
        .PWR
        .constrain()
        .vos(VoltageScale::Range1 { enable_boost: true })
        .freeze();
    let mut rcc = dp.RCC.constrain().freeze(
        Config::pll()
            .pll_cfg(PllConfig {
                mux: PllSrc::HSI,
                m: PllMDiv::DIV_4,
                n: PllNMul::MUL_85,
                r: Some(PllRDiv::DIV_2),
                q: None,
                p: None,
            })
            .boost(true),
        pwr,
    );
    // flash prefetch on (review D12: the main loop runs from flash at 4 wait states, and
    // its interrupt-masked sections delay the control interrupt)
    hw::flash_prefetch_on();
    defmt::info!(
        "acim-firmware {}: {} Hz core, {} Hz PWM, mode: {}",
        env!("CARGO_PKG_VERSION"),
        rcc.clocks.sys_clk.raw(),
        board::PWM_FREQUENCY_HZ,
        MODE
    );

    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let gpioa = dp.GPIOA.split(&mut rcc);
    #[cfg(not(feature = "selftest"))]
    let gpiob = dp.GPIOB.split(&mut rcc);
    #[cfg(not(feature = "selftest"))]
    #[cfg_attr(feature = "x-nucleo-ihm16m1", allow(unused_variables))]
    let gpioc = dp.GPIOC.split(&mut rcc);
    let mut led = gpioa.pa5.into_push_pull_output();

    // commands and replies: USART2 on the ST-LINK virtual COM port
    let Ok(serial) = dp.USART2.usart(
        gpioa.pa2.into_alternate(),
        gpioa.pa3.into_alternate(),
        FullConfig::default()
            .baudrate(board::UART_BAUD.bps())
            .fifo_enable(),
        &mut rcc,
    ) else {
        panic!("USART2 set-up failed")
    };
    let (mut tx, mut rx) = serial.split();
    // judged from the registers, not from the HAL's computed value; after the UART set-up
    // so that a failure is reported there too (the panic handler writes it; at a wrong
    // clock the baud rate may be off, but the RTT log has it as well)
    if let Err(e) = acim_firmware_core::clock::check(&hw::clock_registers(), board::SYSCLK_HZ) {
        defmt::error!("clock set-up wrong: {}", e);
        panic!("system clock is not 170 MHz boost");
    }

    let sincos = board_cfg::sincos(dp.CORDIC, &mut rcc);
    // settings from the two reserved flash pages: the valid record with the newest
    // sequence number, else the defaults; a torn (ECC double error, its NMI handled) or
    // refused page is reported after the ready line (the drive starts Idle anyway)
    let boot = store::load(&mut flash::Pages { poll: &mut || {} });
    let settings = boot.settings;
    match boot.from {
        Some((page, seq)) => defmt::info!("settings loaded from flash page {} (seq {})", page, seq),
        None => defmt::info!("no valid saved settings: defaults"),
    }
    if boot.warning() {
        defmt::warn!("a settings page is torn or refused (reported on the UART)");
    }
    let (cfg, drive) = match build_drive(&settings, sincos) {
        Ok(d) => d,
        Err(e) => {
            defmt::error!("drive configuration rejected: {}", e);
            panic!("drive configuration rejected")
        }
    };
    #[cfg_attr(feature = "selftest", allow(unused_mut))]
    let mut conv = Converter::new(&POWER_STAGE);

    // SAFETY: the queues are split exactly once, here, before the interrupt that uses
    // the other halves is enabled; afterwards each half has exactly one user.
    let (tel_p, mut tel_c) = unsafe { (*core::ptr::addr_of_mut!(TEL_QUEUE)).split() };
    let (cmd_p, cmd_c) = unsafe { (*core::ptr::addr_of_mut!(CMD_QUEUE)).split() };
    let (reply_p, mut reply_c) = unsafe { (*core::ptr::addr_of_mut!(REPLY_QUEUE)).split() };

    #[cfg(not(feature = "selftest"))]
    let irq = {
        use stm32g4xx_hal::pwm::{Polarity, PwmAdvExt};
        // the board's gate enables (if any) driven off before TIM1 drives anything
        hw::gate_enable_init();
        // TIM1: centre-aligned, ARR = 17000 (5 kHz), dead time, break on the board's fault
        // pin (active low: PA6 on the generic stage, PB12 on the X-NUCLEO-IHM16M1)
        #[cfg(not(feature = "x-nucleo-ihm16m1"))]
        let fault = gpioa.pa6;
        #[cfg(feature = "x-nucleo-ihm16m1")]
        let fault = gpiob.pb12;
        let pins = (
            gpioa.pa8.into_alternate(),
            gpioa.pa9.into_alternate(),
            gpioa.pa10.into_alternate(),
        );
        let (_control, (c1, c2, c3)) = dp
            .TIM1
            .pwm_advanced(pins, &mut rcc)
            .prescaler(0)
            .period(board::PWM_ARR)
            .center_aligned()
            .with_deadtime(board::DEAD_TIME_NS.nanos())
            // the fault line is active low (open drain on the power stage): pulled up, so a
            // missing pull on the board reads as "no fault" only while it is driven
            .with_break_pin(
                fault
                    .into_alternate()
                    .internal_resistor(stm32g4xx_hal::gpio::Pull::Up),
                Polarity::ActiveLow,
            )
            .finalize();
        // the HAL leaves MOE set: clear it before any channel is enabled
        hw::tim1_safe_state();
        // complementary outputs on PA7, PB0, PB1 (the profile's low sides); an
        // input/enable driver (X-NUCLEO-IHM16M1) has none: PB0/PB1 are its current inputs
        #[cfg(not(feature = "x-nucleo-ihm16m1"))]
        let (mut c1, mut c2, mut c3) = (
            c1.into_complementary(gpioa.pa7.into_alternate()),
            c2.into_complementary(gpiob.pb0.into_alternate()),
            c3.into_complementary(gpiob.pb1.into_alternate()),
        );
        #[cfg(feature = "x-nucleo-ihm16m1")]
        let (mut c1, mut c2, mut c3) = (c1, c2, c3);
        c1.enable();
        c2.enable();
        c3.enable();
        hw::tim1_polarity();
        hw::tim1_start(board::PWM_ARR, board::PWM_ARR - board::SAMPLE_LEAD_TICKS);

        // ADC pins in analog mode (the profile's plan; generic: ADC1 U current (IN1), bus
        // (IN6); ADC2 V (IN7), W (IN2))
        let _ia = gpioa.pa0.into_analog();
        let _ic = gpioa.pa1.into_analog();
        #[cfg(not(feature = "x-nucleo-ihm16m1"))]
        let (_vbus, _ib) = (gpioc.pc0.into_analog(), gpioc.pc1.into_analog());
        #[cfg(feature = "x-nucleo-ihm16m1")]
        let (_iv, _iw) = (gpiob.pb1.into_analog(), gpiob.pb0.into_analog());
        // the hardware over-current path on those (now analog) amplifier pins, at the
        // drive's trip level, before the outputs are ever enabled
        if !hw::hardware_trip_init(acim::hardware_trip::hardware_trip_level(&cfg)) {
            panic!("hardware over-current DAC did not become ready");
        }
        let mut delay = cp.SYST.delay(&rcc.clocks);
        let adc_ok = hw::adc_init(&hw::InjectedChannels::of_board(), |us| delay.delay_us(us));
        if !adc_ok {
            panic!("ADC power-up or calibration timed out");
        }

        // offset calibration with the switches off (MOE = 0), triggers running
        let mut cal = acim_firmware_core::convert::OffsetCalibrator::new();
        while cal.count() < board::OFFSET_CALIBRATION_SAMPLES {
            match hw::adc_poll(1_000_000) {
                Some(raw) => cal.push(&raw),
                None => panic!("no ADC injected conversions: TIM1 TRGO2 not running?"),
            }
        }
        match cal.finish(&POWER_STAGE) {
            Ok(off) => {
                defmt::info!("current offsets (counts): {}", off);
                conv = conv.with_offsets(off);
            }
            Err(e) => {
                // never run with wrong offsets: outputs stay off until a power cycle
                defmt::error!("offset calibration failed: {}; switches stay off", e);
                hw::uart_fatal(b"current offset calibration failed: ", offset_text(&e));
                halt_safe();
            }
        }
        hw::adc_enable_interrupt();
        pac::Interrupt::ADC1_2
    };

    #[cfg(feature = "selftest")]
    let (irq, _tim6) = {
        use stm32g4xx_hal::timer::{Event, Timer};
        let mut t = Timer::new(dp.TIM6, &rcc.clocks).start_count_down(200.micros());
        t.listen(Event::TimeOut);
        let _ = conv; // nominal offsets: the simulated ADC has none
        (pac::Interrupt::TIM6_DACUNDER, t)
    };

    // every start waits for the drive's own switches-off offset measurement (0.1 s of
    // idle periods, `acim::Drive::start_pending`): "ready" is said once it has run
    let settle_periods = drive.coeffs().limits.offset_settle_steps;
    control_isr::install(IsrState {
        ctl: ControlLoop::new(drive, conv, board::TELEMETRY_DECIMATION),
        tel: tel_p,
        cmd: cmd_c,
        reply: reply_p,
        #[cfg(feature = "selftest")]
        sim: acim_firmware_core::sim::SimulatedStage::new(conv),
        #[cfg(not(feature = "selftest"))]
        outputs: acim_firmware_core::stage::Outputs::default(),
    });
    hw::nvic_enable_top(irq, &mut cp.NVIC);
    // the slow task's interrupt (a slow tick's work, pended by the control interrupt)
    #[cfg(not(feature = "selftest"))]
    hw::nvic_enable_slow_task(&mut cp.NVIC);

    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.start(board::WATCHDOG_TIMEOUT_MS.millis());
    let mut alive = Alive::new(watchdog);
    let first_beat = alive.last_beat;
    while alive.last_beat.wrapping_sub(first_beat) < settle_periods {
        // the watchdog as in the main loop: fed only while the control interrupt is alive
        alive.poll();
    }

    let mut line = RequestAssembler::new();
    let mut out = Uart::new();
    let mut dispatch = Dispatch::new(settings);
    let mut fw = Fw {
        cmd_p,
        cfg,
        rcc,
        alive,
        stream: false,
    };
    const _: () = assert!(board::PWM_FREQUENCY_HZ == 5000, "FIRMWARE_HELLO says 5000");
    raw(&mut out, &protocol::FIRMWARE_HELLO);
    say(&mut out, b"acim-firmware ready (help for commands)\r\n");
    boot.report(&mut out);

    // after a receive overrun: the rest of the cut line is dropped (up to its end)
    let mut rx_discard = false;
    loop {
        // watchdog fed only while the control interrupt is alive; outputs off if it stops
        fw.alive.poll();
        let code = control_isr::STATE_CODE.load(Ordering::Relaxed);
        if code == 1 || code == 2 || code == 3 || code == control::STATE_COMMISSIONING {
            led.set_high();
        } else {
            led.set_low();
        }

        // commands in
        match rx.read() {
            Ok(byte) => {
                if rx_discard {
                    // the line an overrun cut: dropped up to its end
                    rx_discard = !(byte == b'\r' || byte == b'\n');
                } else if let Some(parsed) = line.push(byte) {
                    // replies (also the interrupt's, which come later) go out as the
                    // command came
                    out.framed = parsed.framed;
                    if let Err(e) = parsed.request {
                        defmt::warn!("command rejected: {}", e.as_str());
                    }
                    dispatch.handle(parsed.request, &mut fw, &mut out);
                }
            }
            Err(stm32g4xx_hal::nb::Error::WouldBlock) => {}
            Err(stm32g4xx_hal::nb::Error::Other(e)) => {
                // the line being received is cut: drop what was assembled, and after an
                // overrun also the FIFO's bytes (they precede the lost ones) and the rest
                // of the line up to its end, so no fragment of it can run (review N6)
                line.reset();
                if matches!(e, stm32g4xx_hal::serial::Error::Overrun) {
                    hw::uart_flush_rx();
                    rx_discard = true;
                }
                say(&mut out, b"err uart receive error, line dropped\r\n");
            }
        }

        // replies from the interrupt
        while let Some(CommandReply { command, result }) = reply_c.dequeue() {
            match result {
                Ok(()) => defmt::info!("ok {}", command),
                Err(e) => defmt::warn!("refused {}: {}", command, e),
            }
            dispatch.control_reply(command, result, &mut fw, &mut out);
        }

        // commissioning: the fits once the interrupt has finished it, or its abort
        dispatch.poll(&mut fw);

        // telemetry
        while let Some(s) = tel_c.dequeue() {
            // at debug level (compiled out at the default `info`): a sample's frame is
            // about 2400 instructions of the main loop's time (the logger masks nothing,
            // `rtt.rs`, but the UART's stream has the samples)
            defmt::debug!("{}", s);
            if fw.stream {
                send_sample(&mut out, &s);
            }
        }

        // UART out, non-blocking
        while let Some(&b) = out.q.front() {
            match tx.write(b) {
                Ok(()) => {
                    out.q.pop_front();
                }
                Err(_) => break,
            }
        }
    }
}

#[cfg(target_os = "none")]
/// The main loop's watch on the control interrupt: the watchdog is fed only while the
/// interrupt's heartbeat advances, and if it stops advancing for
/// [`board::ISR_STALL_PERIODS`] PWM periods (counted by TIM1's update flag, which keeps
/// coming while the interrupt does not) the outputs are switched off at once (review N3:
/// the bridge kept switching at frozen duties until the watchdog reset). Polled by the
/// main loop and inside the flash waits of `save`.
struct Alive {
    watchdog: IndependentWatchdog,
    last_beat: u32,
    stalled: u32,
}

#[cfg(target_os = "none")]
impl Alive {
    fn new(watchdog: IndependentWatchdog) -> Self {
        Self {
            watchdog,
            last_beat: control_isr::HEARTBEAT.load(Ordering::Acquire),
            stalled: 0,
        }
    }

    #[inline(never)]
    fn poll(&mut self) {
        let beat = control_isr::HEARTBEAT.load(Ordering::Acquire);
        // a period passed (self-test: TIM1 is not running; the model is never switched)
        let period = !cfg!(feature = "selftest") && hw::take_period_flag();
        if beat != self.last_beat {
            self.last_beat = beat;
            self.stalled = 0;
            self.watchdog.feed();
        } else if period {
            // a missed poll only delays this count: it never counts periods that did not
            // pass (a slow main loop sees one flag for several periods)
            self.stalled += 1;
            if self.stalled >= board::ISR_STALL_PERIODS {
                // masked: a control interrupt that resumes cannot interleave the RMW
                cortex_m::interrupt::free(|_| hw::emergency_off());
            }
        }
    }
}

#[cfg(target_os = "none")]
#[cfg(not(feature = "selftest"))]
/// The reason of a refused offset calibration, for the UART.
fn offset_text(e: &acim_firmware_core::convert::OffsetError) -> &'static [u8] {
    use acim_firmware_core::convert::OffsetError;
    match e {
        OffsetError::NoSamples => b"no samples",
        OffsetError::OutOfTolerance { channel: 0, .. } => b"phase U out of tolerance",
        OffsetError::OutOfTolerance { channel: 1, .. } => b"phase V out of tolerance",
        OffsetError::OutOfTolerance { .. } => b"phase W out of tolerance",
    }
}

#[cfg(target_os = "none")]
/// UART output buffer, bytes (`get` lists every setting in one go).
const OUT_LEN: usize = 1024;

#[cfg(target_os = "none")]
/// The UART's output: its buffer, and whether reply lines go out framed (`$R`/`$E`,
/// protocol 1: the last command came as a `$C` frame) or plain.
struct Uart {
    q: Deque<u8, OUT_LEN>,
    framed: bool,
    /// The reply line being framed, after its `K,` (kind, comma).
    line: heapless::Vec<u8, { protocol::LINE_CAPACITY - 8 }>,
    /// Bytes of the unfinished plain line already queued (taken back if it does not fit).
    partial: usize,
    /// The rest of a plain line that did not fit is being dropped (up to its `\n`).
    dropping: bool,
}

#[cfg(target_os = "none")]
impl Uart {
    fn new() -> Self {
        Self {
            q: Deque::new(),
            framed: false,
            line: heapless::Vec::new(),
            partial: 0,
            dropping: false,
        }
    }
}

#[cfg(target_os = "none")]
#[inline(never)]
fn push(q: &mut Deque<u8, OUT_LEN>, bytes: &[u8]) {
    for &b in bytes {
        if q.push_back(b).is_err() {
            break;
        }
    }
}

#[cfg(target_os = "none")]
/// Bytes as they are (frames, telemetry).
fn raw(out: &mut Uart, bytes: &[u8]) {
    push(&mut out.q, bytes)
}

#[cfg(target_os = "none")]
/// A telemetry sample as its `$T` frame and, protocol 1, its `$X`: together or not at all
/// (a sample the UART has no room for is dropped whole; its `seq` shows the gap).
#[inline(never)]
fn send_sample(out: &mut Uart, s: &TelemetrySample) {
    let t = telemetry::encode(s);
    let x = protocol::encode_extension(&protocol::Extension::of(s));
    if out.q.capacity() - out.q.len() >= t.len() + x.len() {
        raw(out, &t);
        raw(out, &x);
    }
}

#[cfg(target_os = "none")]
/// Reply text: as it is, or each `\r\n`-ended line as one `$R`/`$E` frame (an `err`
/// line is an `$E`), its CRC computed in place.
#[inline(never)]
fn say(out: &mut Uart, text: &[u8]) {
    let Uart {
        q,
        framed,
        line,
        partial,
        dropping,
    } = out;
    if !*framed {
        // whole lines or nothing (review N7: a full queue cut lines and glued them): a
        // line that does not fit is taken back out and the rest of it dropped
        for &b in text {
            if *dropping {
                *dropping = b != b'\n';
                continue;
            }
            if q.push_back(b).is_err() {
                for _ in 0..(*partial).min(q.len()) {
                    q.pop_back();
                }
                *partial = 0;
                *dropping = b != b'\n';
            } else if b == b'\n' {
                *partial = 0;
            } else {
                *partial += 1;
            }
        }
        return;
    }
    for &b in text {
        if line.is_empty() {
            let _ = line.extend_from_slice(b"R,");
        }
        match b {
            b'\r' => {}
            b'\n' => {
                if line[2..].starts_with(b"err") {
                    line[0] = b'E';
                }
                // `$`, the line, `*HHHH\r\n`: the whole frame or nothing
                if q.capacity() - q.len() < line.len() + 8 {
                    line.clear();
                    continue;
                }
                push(q, b"$");
                push(q, line);
                push(q, b"*");
                push(q, &protocol::crc_hex(telemetry::crc16(line)));
                push(q, b"\r\n");
                line.clear();
            }
            _ => {
                let _ = line.push(b);
            }
        }
    }
}

#[cfg(target_os = "none")]
/// Reply lines of the shared command handling: `\r\n`-ended, or framed ([`say`]).
impl Reply for Uart {
    fn put(&mut self, text: &[u8]) {
        say(self, text);
    }
    fn end(&mut self) {
        say(self, b"\r\n");
    }
}

#[cfg(target_os = "none")]
/// What the shared command handling ([`dispatch`]) needs of this board: the interrupt's
/// command queue, the drive's rebuild, the flash page, the telemetry switch.
struct Fw {
    cmd_p: heapless::spsc::Producer<'static, ControlCommand, CMD_Q>,
    /// The configuration of the drive in use (for `params`).
    cfg: acim::DriveConfig,
    rcc: stm32g4xx_hal::rcc::Rcc,
    alive: Alive,
    /// Text telemetry on the UART.
    stream: bool,
}

#[cfg(target_os = "none")]
impl Platform for Fw {
    const NAME: &'static str = BOARD_NAME;
    const PLANT: bool = cfg!(feature = "selftest");
    const RATE_FLOOR: u16 = dispatch::UART_RATE_FLOOR;

    fn send(&mut self, cmd: ControlCommand) -> Sent {
        // the reply ("ok" / the refusal) comes back from the interrupt
        match self.cmd_p.enqueue(cmd) {
            Ok(()) => Sent::Queued,
            Err(_) => Sent::Busy,
        }
    }

    fn state_code(&self) -> u8 {
        control_isr::STATE_CODE.load(Ordering::Relaxed)
    }

    fn fault_code(&self) -> u8 {
        control_isr::FAULT_CODE.load(Ordering::Relaxed)
    }

    fn status(&mut self) -> (u8, u8) {
        let (st, fault) = (self.state_code(), self.fault_code());
        defmt::info!(
            "status: state {}, fault {}, outputs {}, periods {}, telemetry dropped {}",
            st,
            fault,
            hw_outputs_enabled(),
            control_isr::HEARTBEAT.load(Ordering::Relaxed),
            control_isr::TEL_DROPPED.load(Ordering::Relaxed)
        );
        (st, fault)
    }

    fn dc_bus(&self) -> f32 {
        f32::from_bits(control_isr::DC_BUS_BITS.load(Ordering::Relaxed))
    }

    fn periods(&self) -> u32 {
        control_isr::HEARTBEAT.load(Ordering::Relaxed)
    }

    #[inline(never)]
    fn rebuild(&mut self, next: &Settings) -> Result<(), Rebuild> {
        let (cfg, drive) =
            build_drive(next, board_cfg::another(&mut self.rcc)).map_err(Rebuild::Invalid)?;
        control_isr::replace_drive_if_idle(drive).map_err(|_| Rebuild::NotIdle)?;
        self.cfg = cfg;
        // the comparators follow the new trip level
        #[cfg(not(feature = "selftest"))]
        hw::set_hardware_trip(acim::hardware_trip::hardware_trip_level(&cfg));
        Ok(())
    }

    #[inline(never)]
    fn save(&mut self, s: &Settings) -> Result<&'static str, &'static str> {
        // the watchdog keeps being fed (and a stopped interrupt still switches off) while
        // the flash is busy
        let alive = &mut self.alive;
        let mut pages = flash::Pages {
            poll: &mut || alive.poll(),
        };
        match store::save(&mut pages, s) {
            Ok(p) => {
                defmt::info!("settings saved to page {} (seq {})", p.page, p.seq);
                Ok(match p.page {
                    store::Page::A => "saved to flash (page A)",
                    store::Page::B => "saved to flash (page B)",
                })
            }
            Err(e) => {
                let why = match e {
                    store::SaveError::Flash(e) => e.as_str(),
                    store::SaveError::Verify => flash::FlashError::Verify.as_str(),
                };
                defmt::error!("settings save failed: {}", why);
                Err(why)
            }
        }
    }

    #[inline(never)]
    fn params<R: Reply>(&mut self, _s: &Settings, out: &mut R) {
        let cfg = &self.cfg;
        let m = &cfg.machine;
        defmt::info!(
            "params: Ts {} s, flux current {} A, current limit {} A, trip {} A, bus {}..{} V, max speed {} rpm, ramp {} rpm/s, Rs0 {} ohm, Rs estimation {}, dead time {} s, sensing {}, pole pairs {}",
            cfg.loops.control_period,
            cfg.loops.flux_current,
            cfg.limits.current_limit,
            cfg.limits.overcurrent_trip,
            cfg.limits.dc_bus_min,
            cfg.limits.dc_bus_max,
            cfg.limits.max_speed * RAD_S_TO_RPM,
            cfg.loops.speed_ramp * RAD_S_TO_RPM,
            cfg.estimation.rs_initial,
            cfg.estimation.rs_estimation,
            cfg.inverter.dead_time,
            cfg.inverter.current_sensing,
            m.pole_pairs_f32(),
        );
        defmt::info!(
            "board: {}, {} A/count, {} V/count, PWM ARR {}, sample lead {} ticks",
            POWER_STAGE.name,
            POWER_STAGE.amps_per_count(),
            POWER_STAGE.volts_per_count(),
            board::PWM_ARR,
            board::SAMPLE_LEAD_TICKS
        );
        out.line(b"ok parameters logged on RTT (defmt)");
    }

    fn set_stream(&mut self, on: bool) {
        self.stream = on;
    }

    fn stage_commissioning(&mut self, c: Option<acim::commissioning::Commissioning>) {
        control_isr::stage_commissioning(c);
    }

    fn commissioning_progress(&self) -> Option<(acim::commissioning::Stage, f32)> {
        control_isr::commissioning_progress()
    }

    fn take_finished_commissioning(&mut self) -> Option<acim::commissioning::Commissioning> {
        let c = control_isr::take_finished_commissioning();
        if c.is_some() {
            defmt::info!("commissioning finished");
        }
        c
    }
}

#[cfg(target_os = "none")]
/// The drive for `s` (the one place a drive is built: at boot, on `set`, `defaults` and
/// `commission apply`).
#[inline(never)]
fn build_drive(
    s: &Settings,
    sincos: board_cfg::Sc,
) -> Result<(acim::DriveConfig, Drive<board_cfg::Sc>), settings::SettingError> {
    let cfg = s.drive_config()?;
    Ok((cfg, Drive::with_sincos(cfg, sincos)?))
}

#[cfg(target_os = "none")]
fn hw_outputs_enabled() -> bool {
    if cfg!(feature = "selftest") {
        false
    } else {
        hw::outputs_enabled()
    }
}

#[cfg(target_os = "none")]
/// Switches off and waits for a power cycle (called before the watchdog is started, so
/// the board stays halted with its outputs off instead of resetting in a loop).
#[cfg(not(feature = "selftest"))]
fn halt_safe() -> ! {
    hw::emergency_off();
    loop {
        cortex_m::asm::wfi();
    }
}

#[cfg(target_os = "none")]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // switches off first, before anything that could fail
    cortex_m::interrupt::disable();
    hw::emergency_off();
    // on the UART too (review N8): the user of the virtual COM port sees why
    let msg = info.message().as_str().unwrap_or("(formatted message)");
    hw::uart_fatal(b"panic: ", msg.as_bytes());
    // location and static message only: formatting arbitrary panic arguments would link
    // core::fmt's float machinery (~15 KB) for nothing
    match info.location() {
        Some(l) => defmt::error!("panic at {}:{}: {}", l.file(), l.line(), msg),
        None => defmt::error!("panic: {}", msg),
    }
    // the independent watchdog (if started) resets the MCU; the drive restarts idle
    loop {
        cortex_m::asm::nop();
    }
}

#[cfg(target_os = "none")]
#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    hw::emergency_off();
    loop {
        cortex_m::asm::nop();
    }
}

#[cfg(target_os = "none")]
/// MemManage: the stack ran into its guard (review D16): switch off, then wait for the
/// watchdog.
#[exception]
unsafe fn MemoryManagement() {
    hw::emergency_off();
    loop {
        cortex_m::asm::nop();
    }
}

#[cfg(target_os = "none")]
/// NMI: a flash ECC double error in a settings page (a save torn by a power cut) is
/// cleared and noted for that page, and the read carries on (the page is then refused as
/// torn, and the other page's record used); anything else switches off, then waits for
/// the watchdog.
#[exception]
unsafe fn NonMaskableInt() {
    if flash::ecc_error_in_settings() {
        return;
    }
    hw::emergency_off();
    loop {
        cortex_m::asm::nop();
    }
}

#[cfg(target_os = "none")]
/// Any exception or interrupt without a handler: switch off, then wait for the watchdog.
#[exception]
unsafe fn DefaultHandler(_irqn: i16) {
    hw::emergency_off();
    loop {
        cortex_m::asm::nop();
    }
}
