//! Board description: NUCLEO-G474RE + a power stage. What differs between power stages
//! (pins, gate polarity, enables, fault input, ADC plan, measurement chain, ratings) is a
//! board profile ([`crate::profile`], selected by a cargo feature: [`BOARD`]); the timing
//! and protection constants common to them live here. The default profile, and the pin map
//! below, is a generic three-shunt IGBT inverter for a 230 V induction motor.
//!
//! **The power-stage values below are assumptions, not measurements: check them against the
//! schematic of the power stage actually connected before applying the DC bus.** They
//! describe a typical 230 VAC, ~1 kW three-shunt IGBT board (the class of ST's
//! STEVAL-IHM028V2 / STEVAL-IHM023V3 inverters): low-side shunts with a non-inverting
//! amplifier biased at mid-supply, a resistive DC-bus divider, active-high gate inputs
//! with pull-downs, and an active-low open-drain fault line (gate-driver / over-current
//! comparator) wired to the timer's break input.
//!
//! Pin map (NUCLEO-G474RE Morpho/Arduino headers; AF = alternate function number):
//!
//! | MCU pin | function | signal | NUCLEO header |
//! |---|---|---|---|
//! | PA8  | TIM1_CH1  (AF6) | phase U high-side gate | Arduino D7 |
//! | PA9  | TIM1_CH2  (AF6) | phase V high-side gate | Arduino D8 |
//! | PA10 | TIM1_CH3  (AF6) | phase W high-side gate | Arduino D2 |
//! | PA7  | TIM1_CH1N (AF6) | phase U low-side gate  | Arduino D11 |
//! | PB0  | TIM1_CH2N (AF6) | phase V low-side gate  | Arduino A3 |
//! | PB1  | TIM1_CH3N (AF6) | phase W low-side gate  | Morpho CN10 |
//! | PA6  | TIM1_BKIN (AF6) | fault, active low (open drain, pull-up on the power board) | Arduino D12 |
//! | PA0  | ADC1_IN1  | phase U current amplifier output | Arduino A0 |
//! | PC1  | ADC2_IN7  | phase V current amplifier output | Arduino A4 |
//! | PA1  | ADC2_IN2  | phase W current amplifier output | Arduino A1 |
//! | PC0  | ADC1_IN6  | DC-bus divider output | Arduino A5 |
//! | PA2 / PA3 | USART2 TX / RX (AF7) | commands and replies, ST-LINK virtual COM port | (on board) |
//! | PA5  | GPIO | LD2 green LED: on while the switches are enabled | (on board) |
//!
//! Ground: the power stage's signal ground to a NUCLEO GND pin; its logic supply must be
//! 3.3 V compatible (the G474 pins above are 3.3 V; PA0/PA1/PC0/PC1 are not 5 V tolerant
//! in analog mode).

use crate::profile::{self, BoardProfile};
use acim::{CurrentSensing, DriveConfig};

/// Core clock after `freeze` (PLL from HSI16: 16 MHz / 4 * 85 / 2), Hz. Also TIM1's clock.
pub const SYSCLK_HZ: u32 = 170_000_000;

/// PWM and control frequency, Hz (the paper's 5 kHz; configurable here).
pub const PWM_FREQUENCY_HZ: u32 = 5_000;

/// Control period, s.
pub const CONTROL_PERIOD_S: f32 = 1.0 / PWM_FREQUENCY_HZ as f32;

/// Centre-aligned PWM auto-reload value: the counter runs 0 -> ARR -> 0 once per period,
/// so ARR = f_tim / (2 f_pwm) (17 000 at 170 MHz and 5 kHz: 5.9 ns resolution).
pub const fn pwm_arr(sysclk_hz: u32, pwm_hz: u32) -> u32 {
    sysclk_hz / (2 * pwm_hz)
}

/// TIM1 auto-reload value for [`PWM_FREQUENCY_HZ`].
pub const PWM_ARR: u16 = {
    let arr = pwm_arr(SYSCLK_HZ, PWM_FREQUENCY_HZ);
    assert!(
        arr > 1000 && arr <= 0xFFFF,
        "PWM frequency out of the 16-bit timer range"
    );
    arr as u16
};

/// Dead time inserted by TIM1 between complementary switches, ns (power-stage dependent:
/// at least the IGBTs' turn-off time plus driver skew).
pub const DEAD_TIME_NS: u32 = 1_500;

/// The ADC's sampling window is centred on the counter peak (mid low-side-on time). The
/// injected trigger (TRGO2 = OC4REF rising edge, CCR4 = ARR - lead) fires this long
/// before the peak: half the first rank's sampling time (24.5 ADC clocks at 42.5 MHz).
pub const SAMPLE_LEAD_NS: u32 = 290;

/// TIM1 ticks between the trigger and the counter peak.
pub const SAMPLE_LEAD_TICKS: u16 =
    ((SYSCLK_HZ as u64 * SAMPLE_LEAD_NS as u64) / 1_000_000_000) as u16;

/// Shunt amplifier settling after the low-side switch turns on, ns (power-stage
/// dependent: the amplifier's slew and settling to 12 bits; check on a scope).
pub const AMPLIFIER_SETTLING_NS: u32 = 1_000;
/// Sampling time of one rank: 24.5 ADC clocks at 42.5 MHz, ns.
pub const SAMPLING_TIME_NS: u32 = 577;
/// The low side conducts from a dead time after OCxREF falls, (1 - d) T / 2 - DT before
/// the counter peak, to (1 - d) T / 2 after it. The sample (centred on the peak) is valid
/// only if the switch closed and the amplifier settled before the window opens:
/// (1 - d) T / 2 >= DT + t_settle + t_s / 2. The dead time is taken as programmed (TIM1
/// rounds [`DEAD_TIME_NS`] up to 256 ticks = 1506 ns).
pub const LOW_SIDE_HALF_WINDOW_NS: u32 = 1_506 + AMPLIFIER_SETTLING_NS + SAMPLING_TIME_NS / 2;
/// Largest high-side duty, from [`LOW_SIDE_HALF_WINDOW_NS`]: 1 - 2 (DT + t_settle + t_s/2)
/// f_pwm = 0.972 at 5 kHz (firmware review D4: the former 0.985 left the window opening
/// 0.22 us before the switch closed).
pub const MAX_DUTY: f32 =
    1.0 - 2.0 * LOW_SIDE_HALF_WINDOW_NS as f32 * 1e-9 * PWM_FREQUENCY_HZ as f32;

/// Electrical description of the power stage's measurement chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowerStage {
    /// Human-readable description.
    pub name: &'static str,
    /// Number of phase shunts (2 or 3).
    pub shunts: u8,
    /// Shunt resistance, ohm.
    pub shunt_ohm: f32,
    /// Current amplifier gain, V/V.
    pub amplifier_gain: f32,
    /// Amplifier output at zero current (mid-supply bias), V.
    pub amplifier_bias_v: f32,
    /// +1 if the amplifier output rises with a current flowing into the motor, -1 if it
    /// falls (a low-side shunt sees the motor current flowing out of DC-: usually -1).
    pub current_sign: f32,
    /// DC-bus divider, upper resistance, ohm.
    pub divider_top_ohm: f32,
    /// DC-bus divider, lower resistance (the one the ADC sees), ohm.
    pub divider_bottom_ohm: f32,
    /// ADC reference voltage, V (VREF+ = VDDA = 3.3 V on the NUCLEO).
    pub adc_vref: f32,
    /// ADC full-scale count + 1 (4096 for 12 bits).
    pub adc_counts: u32,
}

impl PowerStage {
    /// Phase current per ADC count, A (signed by `current_sign`).
    pub const fn amps_per_count(&self) -> f32 {
        self.current_sign * self.adc_vref
            / (self.adc_counts as f32 * self.shunt_ohm * self.amplifier_gain)
    }
    /// DC-bus voltage per ADC count, V.
    pub const fn volts_per_count(&self) -> f32 {
        self.adc_vref / self.adc_counts as f32 * (self.divider_top_ohm + self.divider_bottom_ohm)
            / self.divider_bottom_ohm
    }
    /// ADC count of the amplifier bias (zero current), nominal.
    pub const fn bias_counts(&self) -> f32 {
        self.amplifier_bias_v / self.adc_vref * self.adc_counts as f32
    }
    /// Largest measurable current magnitude, A (the smaller side of the bias).
    pub const fn current_full_scale(&self) -> f32 {
        let lo = self.amplifier_bias_v;
        let hi = self.adc_vref - self.amplifier_bias_v;
        let headroom = if lo < hi { lo } else { hi };
        headroom / (self.shunt_ohm * self.amplifier_gain)
    }
    /// DC-bus voltage at ADC full scale, V.
    pub const fn bus_full_scale(&self) -> f32 {
        self.adc_vref * (self.divider_top_ohm + self.divider_bottom_ohm) / self.divider_bottom_ohm
    }
}

/// The board profile this build is for ([`crate::profile`]): the generic stage by
/// default, another with the `acim-firmware` feature of its name.
pub const BOARD: BoardProfile = if cfg!(feature = "x-nucleo-ihm16m1") {
    profile::X_NUCLEO_IHM16M1
} else if cfg!(feature = "steval-ihm023v3") {
    profile::STEVAL_IHM023V3
} else {
    profile::GENERIC
};
#[cfg(all(feature = "x-nucleo-ihm16m1", feature = "steval-ihm023v3"))]
compile_error!("select one board profile feature");

/// The power stage's measurement chain (see the module documentation: **values to be
/// checked**): [`BOARD`]'s.
pub const POWER_STAGE: PowerStage = BOARD.stage;

/// Offset calibration: number of samples averaged with the switches off (0.2 s at 5 kHz).
pub const OFFSET_CALIBRATION_SAMPLES: u32 = 1024;

/// Offset calibration: largest accepted distance of a measured offset from the nominal
/// bias, ADC counts (150 counts = 0.12 V; beyond it the amplifier or wiring is suspect).
pub const OFFSET_TOLERANCE_COUNTS: f32 = 150.0;

/// Telemetry decimation: one sample every this many control periods (10 Hz at 5 kHz).
pub const TELEMETRY_DECIMATION: u16 = 500;

/// Largest speed command accepted by the parser, rpm (the drive clamps further to 90 %
/// of its over-speed limit).
pub const MAX_SPEED_COMMAND_RPM: f32 = 1800.0;

/// DC-bus and protection limits for one way of powering the stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusProfile {
    /// Name, printed at boot.
    pub name: &'static str,
    /// Lowest DC bus while switching, V.
    pub dc_bus_min: f32,
    /// Highest DC bus, V.
    pub dc_bus_max: f32,
    /// Phase current limit of the speed loop, A peak.
    pub current_limit: f32,
    /// Phase current trip, A peak.
    pub overcurrent_trip: f32,
    /// Over-speed trip, rpm.
    pub max_speed_rpm: f32,
}

/// Rectified 230 VAC mains (325 V nominal): the project's defaults.
pub const MAINS: BusProfile = BusProfile {
    name: "mains 200-400 V",
    dc_bus_min: 200.0,
    dc_bus_max: 400.0,
    current_limit: acim::params::DEFAULT_CURRENT_LIMIT,
    overcurrent_trip: 8.0,
    max_speed_rpm: 2000.0,
};

/// First power-up from a current-limited 24-60 V bench supply: the bus window brackets the
/// supply, the current limit and trip are low, and the speed limit matches what the
/// voltage can drive (the paper's motor reaches about 100 rpm at 48 V). Selected with the
/// firmware's `low-voltage` feature (`firmware/README.md`, bring-up).
pub const LOW_VOLTAGE: BusProfile = BusProfile {
    name: "low-voltage bring-up 20-66 V",
    dc_bus_min: 20.0,
    dc_bus_max: 66.0,
    current_limit: 2.5,
    overcurrent_trip: 4.0,
    max_speed_rpm: 300.0,
};

/// The bus profile this build uses: the board's first-power-up profile with the
/// `low-voltage` feature, else its default ([`MAINS`] on the generic stage).
pub const PROFILE: BusProfile = if cfg!(feature = "low-voltage") {
    BOARD.low_voltage
} else {
    BOARD.bus
};

/// Independent watchdog timeout, ms (the main loop feeds it only while the control
/// interrupt is alive, also inside the flash waits of `save`). It resets a hung main
/// loop; a stopped control interrupt is switched off much sooner, by the main loop
/// ([`ISR_STALL_PERIODS`]).
pub const WATCHDOG_TIMEOUT_MS: u32 = 20;

/// PWM periods without a control-interrupt heartbeat after which the main loop clears
/// MOE (0.6 ms at 5 kHz; the interrupt runs once per period).
pub const ISR_STALL_PERIODS: u32 = 3;

/// TIM1 break input filter, BDTR.BKF (RM0440: 0b1000 = f_DTS / 8, N = 6: a fault pulse
/// must last 6 samples at 21.25 MHz, 282 ns, to clear MOE). Long enough against gate-drive
/// noise on the fault line, short against an IGBT's short-circuit withstand time (5-10 us).
pub const BREAK_FILTER: u8 = BOARD.fault.filter;
const _: () = assert!(BREAK_FILTER < 16);

/// ADC sampling time code of the bus divider's channel (0b110 = 247.5 cycles, 5.8 us at
/// 42.5 MHz): the divider's source impedance (990 k || 6.8 k, about 6.8 k) on a slow
/// channel needs far more than the current channels' 24.5 cycles. The bus is converted
/// after the U current (ADC1 rank 2), so only the interrupt's start moves later (by about
/// 5.2 us of its 200 us period), not the current sampling instant.
pub const BUS_SMP: u8 = 0b110;
const _: () = assert!(BUS_SMP < 8);

/// USART2 baud rate (ST-LINK virtual COM port).
pub const UART_BAUD: u32 = 115_200;

/// The drive configuration for this board: the project's defaults for the paper's machine
/// with this board's control period, dead time and current sensing.
pub fn drive_config() -> DriveConfig {
    drive_config_for(&PROFILE)
}

/// The drive configuration for this board with the bus profile `p`.
pub fn drive_config_for(p: &BusProfile) -> DriveConfig {
    drive_config_with(&BOARD, p)
}

/// The drive configuration for board `b` with the bus profile `p`.
pub fn drive_config_with(b: &BoardProfile, p: &BusProfile) -> DriveConfig {
    let mut cfg = DriveConfig::paper_defaults();
    cfg.limits.dc_bus_min = p.dc_bus_min;
    cfg.limits.dc_bus_max = p.dc_bus_max;
    cfg.limits.current_limit = p.current_limit;
    cfg.limits.overcurrent_trip = p.overcurrent_trip;
    cfg.limits.max_speed = p.max_speed_rpm * acim::math::RPM_TO_RAD_S;
    cfg.loops.control_period = CONTROL_PERIOD_S;
    cfg.inverter.dead_time = DEAD_TIME_NS as f32 * 1e-9;
    cfg.inverter.current_sensing = if b.stage.shunts >= 3 {
        CurrentSensing::ThreePhase
    } else {
        CurrentSensing::TwoPhase
    };
    // the trip level must stay inside the measurable range (saturation also trips)
    let fs = b.stage.current_full_scale();
    if cfg.limits.overcurrent_trip > 0.9 * fs {
        cfg.limits.overcurrent_trip = 0.9 * fs;
    }
    cfg
}

/// Size of the stack guard, bytes (an MPU region of 2^(SIZE+1) bytes, SIZE = 9, aligned to
/// its size): larger than any single stack frame of the firmware, so that no function's
/// frame can step over the guard into the statics (a 32-byte guard, the MPU's smallest,
/// would catch only pushes); 1 KiB of the 92 KiB of SRAM the firmware leaves free.
pub const STACK_GUARD_BYTES: u32 = 1024;
const STACK_GUARD_SIZE_FIELD: u32 = 9;

/// The MPU region that guards the stack (review D16): `(RBAR, RASR)` for region 0, a
/// no-access, execute-never region of [`STACK_GUARD_BYTES`] at the first boundary of its
/// size at or above `end_of_statics` (cortex-m-rt's `__sheap`: the end of `.bss`/`.uninit`,
/// above which only the main stack lives, growing down from the top of SRAM). A stack
/// that overflows writes into it and faults (MemManage; or LOCKUP when the fault's own
/// stacking hits the guard, which SYSCFG_CFGR2.CLL turns into a TIM1 system break) instead
/// of silently corrupting the SPSC queues and the RTT control block below it.
pub const fn stack_guard_region(end_of_statics: u32) -> (u32, u32) {
    let base = (end_of_statics + STACK_GUARD_BYTES - 1) & !(STACK_GUARD_BYTES - 1);
    // RBAR: ADDR (bits 31:5), VALID = 0 (the region number comes from RNR)
    let rbar = base;
    // RASR: XN (28), AP = 000 no access (26:24), TEX/S/C/B = 0, SRD = 0,
    // SIZE (bits 5:1, 2^(SIZE+1) bytes), ENABLE (0)
    let rasr = (1 << 28) | (STACK_GUARD_SIZE_FIELD << 1) | 1;
    (rbar, rasr)
}

/// MPU_CTRL for the guard: ENABLE, and PRIVDEFENA (the default memory map stays in force
/// everywhere else; the firmware runs privileged), HFNMIENA off (the fault handlers run
/// without the MPU, so they can still switch off).
pub const MPU_CTRL_GUARD: u32 = 0b101;

#[cfg(test)]
mod tests {
    use super::*;

    /// D16: the guard starts at the first boundary of its size at or above the statics,
    /// is 1 KiB, no access, execute-never, and enabled.
    #[test]
    fn the_stack_guard_sits_on_the_statics_and_denies_access() {
        for (end, base) in [
            (0x2000_0878, 0x2000_0C00),
            (0x2000_0C00, 0x2000_0C00),
            (0x2000_0C01, 0x2000_1000),
        ] {
            let (rbar, rasr) = stack_guard_region(end);
            assert_eq!(rbar, base);
            assert_eq!(rbar % STACK_GUARD_BYTES, 0);
            assert_eq!(1u32 << (((rasr >> 1) & 0x1F) + 1), STACK_GUARD_BYTES);
            assert_eq!((rasr >> 24) & 0b111, 0, "AP: no access");
            assert_eq!(rasr & (1 << 28), 1 << 28, "execute-never");
            assert_eq!(rasr & 1, 1, "enabled");
        }
        assert_eq!(MPU_CTRL_GUARD & 0b111, 0b101);
    }
    use acim::Drive;

    #[test]
    fn timer_values() {
        assert_eq!(PWM_ARR, 17_000);
        assert_eq!(SAMPLE_LEAD_TICKS, 49);
        assert!((CONTROL_PERIOD_S - 200e-6).abs() < 1e-9);
        const { assert!(MAX_DUTY > 0.96 && MAX_DUTY < 0.98) };
    }

    /// At the largest duty the low side has closed, and the amplifier settled, before the
    /// sampling window (centred on the counter peak) opens.
    #[test]
    fn max_duty_leaves_the_sampling_window_valid() {
        let period_ns = 1e9 / PWM_FREQUENCY_HZ as f64;
        let low_on_half = (1.0 - MAX_DUTY as f64) * period_ns / 2.0;
        // the dead time as TIM1 programs it (DTG = 0xC0: 8 * 32 ticks at 170 MHz)
        let dead_time = 256.0 / SYSCLK_HZ as f64 * 1e9;
        assert!(dead_time >= DEAD_TIME_NS as f64);
        let needed = dead_time + AMPLIFIER_SETTLING_NS as f64 + SAMPLING_TIME_NS as f64 / 2.0;
        assert!(
            low_on_half >= needed - 1.0,
            "{low_on_half} ns < {needed} ns"
        );
        // the trigger leads the peak by half the sampling time
        assert!((SAMPLE_LEAD_NS as f64 - SAMPLING_TIME_NS as f64 / 2.0).abs() < 5.0);
    }

    #[test]
    fn power_stage_scales() {
        let s = POWER_STAGE;
        // 3.3 V / 4096 / (0.033 ohm * 5) = 4.88 mA per count, negative sign
        assert!((s.amps_per_count() + 3.3 / 4096.0 / 0.165).abs() < 1e-7);
        assert!((s.current_full_scale() - 10.0).abs() < 1e-4);
        assert!((s.bias_counts() - 2048.0).abs() < 1e-3);
        // divider: 3.3 V at the ADC is 483.7 V on the bus
        assert!((s.bus_full_scale() - 483.7).abs() < 0.1);
        assert!(
            s.bus_full_scale() > 400.0,
            "bus trip level must be measurable"
        );
    }

    /// Both profiles give a valid drive; the low-voltage one accepts a 24-60 V supply and
    /// trips below and above it.
    #[test]
    fn bus_profiles_are_valid_drives() {
        for p in [MAINS, LOW_VOLTAGE] {
            let cfg = drive_config_for(&p);
            assert!(Drive::new(cfg).is_ok(), "{}", p.name);
            assert!(p.dc_bus_max < POWER_STAGE.bus_full_scale(), "{}", p.name);
            assert!(
                cfg.limits.overcurrent_trip <= 0.9 * POWER_STAGE.current_full_scale() + 1e-6,
                "{}",
                p.name
            );
        }
        const { assert!(LOW_VOLTAGE.dc_bus_min < 24.0 && LOW_VOLTAGE.dc_bus_max > 60.0) };
        // a bench supply must not run the mains profile
        const { assert!(MAINS.dc_bus_min > 60.0) };
    }

    #[test]
    fn drive_config_is_accepted() {
        let cfg = drive_config();
        assert!(cfg.limits.overcurrent_trip <= 0.9 * POWER_STAGE.current_full_scale() + 1e-6);
        assert!(Drive::new(cfg).is_ok());
    }
}
