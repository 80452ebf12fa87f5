//! Board profiles as data: everything that differs between the power stages the NUCLEO-G474RE
//! drives (gate pins and their polarity and idle levels, enable pins and their sequencing,
//! the fault input, the ADC channel plan, the measurement chain, the ratings), as `const`
//! values checked at compile time ([`BoardProfile::check`], evaluated in a `const` item for
//! every profile: a profile that breaks a rule does not build).
//!
//! The firmware's pin, GPIO, TIM1 polarity / idle-level and ADC set-up read
//! [`crate::board::BOARD`], which a cargo feature of `acim-firmware` selects:
//!
//! | profile | feature |
//! |---|---|
//! | [`GENERIC`]: the generic three-shunt IGBT inverter (the default build, unchanged) | none |
//! | [`X_NUCLEO_IHM16M1`]: ST X-NUCLEO-IHM16M1 (STSPIN830, 7-45 V) | `x-nucleo-ihm16m1` |
//! | [`STEVAL_IHM023V3`]: an L6390-driven IGBT stage, STEVAL-IHM023V3 / IHM028V2 class | `steval-ihm023v3` |
//!
//! **Every number of a profile is to be checked against the schematic of the board
//! connected** (`firmware/bringup.md` has a checklist per profile). The sources: the
//! NUCLEO-G474RE's Arduino/Morpho headers and the G474's alternate-function and ADC-channel
//! tables for the pins; for the X-NUCLEO-IHM16M1 the pin map of its user manual (UM2415)
//! as published in board support packages for the same headers (enables PB13-15,
//! EN_FAULT PB12, currents PA1/PB1/PB0, bus PA0) and the scaling the firmware review
//! measured (0.33 ohm, gain 1.53, 169 k / 9.31 k); for the L6390 its datasheet (LIN active
//! low, with an internal pull-up; HIN active high).

use crate::board::{BusProfile, PowerStage, LOW_VOLTAGE, MAINS};

/// A GPIO port of the LQFP64 package.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Port {
    /// GPIOA.
    A,
    /// GPIOB.
    B,
    /// GPIOC.
    C,
}

/// An MCU pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pin {
    /// Its port.
    pub port: Port,
    /// Its number in the port, 0..=15.
    pub n: u8,
}

/// Pin `PAn`.
pub const fn pa(n: u8) -> Pin {
    Pin { port: Port::A, n }
}
/// Pin `PBn`.
pub const fn pb(n: u8) -> Pin {
    Pin { port: Port::B, n }
}
/// Pin `PCn`.
pub const fn pc(n: u8) -> Pin {
    Pin { port: Port::C, n }
}

impl Pin {
    /// Same pin (a `const` comparison).
    pub const fn is(self, o: Pin) -> bool {
        self.port as u8 == o.port as u8 && self.n == o.n
    }
    /// The GPIO port's base address (AHB2).
    pub const fn gpio_base(self) -> u32 {
        0x4800_0000 + 0x400 * self.port as u32
    }
}

/// How the three half-bridges are driven.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GateDrive {
    /// Two inputs per phase: TIM1 CHx to the high side, CHxN to the low side, with TIM1's
    /// dead time.
    Complementary {
        /// The low-side pins (TIM1_CH1N, CH2N, CH3N).
        low_side: [Pin; 3],
        /// The low-side inputs switch on at a low level (CCxNP = 1, idle OISxN = 1).
        low_active_low: bool,
    },
    /// One input per phase (TIM1 CHx: high selects the high side, low the low side) and
    /// one enable per phase (low: both switches off); the driver makes its own dead time.
    InputEnable {
        /// The enable pins (GPIO outputs).
        enable: [Pin; 3],
    },
}

/// The gate inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gates {
    /// The high-side (or phase-input) pins: TIM1_CH1, CH2, CH3 on PA8, PA9, PA10 (AF6).
    pub high_side: [Pin; 3],
    /// The high-side inputs switch on at a low level (CCxP = 1, idle OISx = 1).
    pub high_active_low: bool,
    /// The low sides.
    pub drive: GateDrive,
}

impl Gates {
    /// TIM1_CCER polarity bits (CCxP, CCxNP) of this drive.
    pub const fn ccer_polarity(&self) -> u32 {
        let mut bits = 0;
        if self.high_active_low {
            bits |= (1 << 1) | (1 << 5) | (1 << 9);
        }
        if let GateDrive::Complementary {
            low_active_low: true,
            ..
        } = self.drive
        {
            bits |= (1 << 3) | (1 << 7) | (1 << 11);
        }
        bits
    }
    /// TIM1_CR2 idle-state bits (OISx, OISxN): each output's *off* level, driven while MOE
    /// is clear (OSSI = 1). Active-high inputs idle low, active-low inputs idle high.
    pub const fn idle_bits(&self) -> u32 {
        let mut bits = 0;
        if self.high_active_low {
            bits |= (1 << 8) | (1 << 10) | (1 << 12);
        }
        if let GateDrive::Complementary {
            low_active_low: true,
            ..
        } = self.drive
        {
            bits |= (1 << 9) | (1 << 11) | (1 << 13);
        }
        bits
    }
    /// The enable pins, if the drive has them.
    pub const fn enable(&self) -> Option<[Pin; 3]> {
        match self.drive {
            GateDrive::InputEnable { enable } => Some(enable),
            GateDrive::Complementary { .. } => None,
        }
    }
    /// Whether TIM1 drives complementary outputs.
    pub const fn complementary(&self) -> bool {
        matches!(self.drive, GateDrive::Complementary { .. })
    }
}

/// The fault line into TIM1's break input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    /// The pin (TIM1_BKIN, AF6: PA6 or PB12).
    pub pin: Pin,
    /// Active low (an open-drain fault output): the break polarity, and the internal
    /// pull-up that keeps a floating line inactive.
    pub active_low: bool,
    /// TIM1_BDTR.BKF, the break filter code (0..=15).
    pub filter: u8,
}

/// What an ADC input measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Signal {
    /// Phase U current amplifier.
    CurrentU,
    /// Phase V current amplifier.
    CurrentV,
    /// Phase W current amplifier.
    CurrentW,
    /// DC-bus divider.
    Bus,
}

/// One injected rank: the pin, its channel number on that ADC, and what it measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdcInput {
    /// The pin (analog mode).
    pub pin: Pin,
    /// Its channel number on the ADC of the rank.
    pub channel: u8,
    /// What it carries.
    pub signal: Signal,
}

/// The injected sequences: two ranks on ADC1, two on ADC2, both triggered by TIM1 TRGO2.
/// Rank 1 of both converts at the counter peak; rank 2 follows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdcPlan {
    /// ADC1 rank 1, rank 2.
    pub adc1: [AdcInput; 2],
    /// ADC2 rank 1, rank 2.
    pub adc2: [AdcInput; 2],
}

impl AdcPlan {
    /// The four results in the order the firmware reads them (ADC1 rank 1, ADC2 rank 1,
    /// ADC2 rank 2, ADC1 rank 2): the slot of `signal`.
    pub const fn slot(&self, signal: Signal) -> usize {
        let order = [self.adc1[0], self.adc2[0], self.adc2[1], self.adc1[1]];
        let mut i = 0;
        while i < 4 {
            if order[i].signal as u8 == signal as u8 {
                return i;
            }
            i += 1;
        }
        panic!("signal not in the plan")
    }
    /// The bus divider's channel and ADC (1 or 2): the long sampling time.
    pub const fn bus(&self) -> (u8, u8) {
        let s = self.slot(Signal::Bus);
        let input = [self.adc1[0], self.adc2[0], self.adc2[1], self.adc1[1]][s];
        (input.channel, if s == 0 || s == 3 { 1 } else { 2 })
    }
}

/// One of the G474's comparators on a current-sense amplifier output, its inverting input
/// on an internal DAC channel (RM0440, chapter "Comparator (COMP)"; the input assignment as in ST's
/// STM32G4 HAL, `stm32g4xx_hal_comp.h`: [`comp_input_pin`], [`comp_dac`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SenseComparator {
    /// COMP1..COMP7.
    pub comp: u8,
    /// COMPx_CSR.INPSEL: false for the comparator's input IO1, true for IO2.
    pub io2: bool,
    /// The amplifier output it watches (its pin is the ADC plan's pin of that signal).
    pub signal: Signal,
}

/// The hardware over-current path: comparators with DAC thresholds on the current-sense
/// amplifier outputs into TIM1's break 2 input (TIM1_AF2.BK2CMPxE, BDTR.BK2E), as ST's
/// application notes for the G4 do it (AN4232 on its comparators, AN4277 on the PWM
/// shut-down): MOE is cleared in hardware within the comparator's propagation and the
/// break filter, whatever the control interrupt does. Each comparator watches its phase in one direction (the current into the motor:
/// the LQFP64's pins reach one comparator input each), and the pins decide which phases a
/// board can watch at all.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HardwareTrip {
    /// The comparators (at most three, one per phase).
    pub comparators: &'static [SenseComparator],
    /// TIM1_BDTR.BK2F, the break-2 filter code (0..=15).
    pub filter: u8,
}

impl HardwareTrip {
    /// The DAC channels its comparators use, each once (comparators may share one): (DAC
    /// 3 or 4, channel 1 or 2), unused slots `None`.
    pub const fn dac_channels(&self) -> [Option<(u8, u8)>; 3] {
        let mut out = [None; 3];
        let mut n = 0;
        let mut i = 0;
        while i < self.comparators.len() && n < 3 {
            if let Some(dc) = comp_dac(self.comparators[i].comp) {
                let mut seen = false;
                let mut j = 0;
                while j < n {
                    if let Some((d, c)) = out[j] {
                        seen |= d == dc.0 && c == dc.1;
                    }
                    j += 1;
                }
                if !seen {
                    out[n] = Some(dc);
                    n += 1;
                }
            }
            i += 1;
        }
        out
    }
}

/// The non-inverting input pin of COMPx (`comp` 1..=7) for INPSEL = `io2`: IO1 = PA1,
/// PA7, PA0, PB0, PB13, PB11, PB14 and IO2 = PB1, PA3, PC1, PE7, PD12, PD11, PD14 for
/// COMP1..7 (RM0440, COMP chapter, COMP pins and internal signals; the same table in
/// ST's `stm32g4xx_hal_comp.h`, `COMP_INPUT_PLUS_IO1/IO2`). `None` for a pin outside the
/// LQFP64's ports A-C as this module describes them, or no such comparator.
pub const fn comp_input_pin(comp: u8, io2: bool) -> Option<Pin> {
    match (comp, io2) {
        (1, false) => Some(pa(1)),
        (1, true) => Some(pb(1)),
        (2, false) => Some(pa(7)),
        (2, true) => Some(pa(3)),
        (3, false) => Some(pa(0)),
        (3, true) => Some(pc(1)),
        (4, false) => Some(pb(0)),
        (5, false) => Some(pb(13)),
        (6, false) => Some(pb(11)),
        (7, false) => Some(pb(14)),
        _ => None,
    }
}

/// The DAC channel on COMPx's inverting input with COMPx_CSR.INMSEL = 0b100: DAC3 CH1 for
/// COMP1/3, DAC3 CH2 for COMP2/4, DAC4 CH1 for COMP5/7, DAC4 CH2 for COMP6 (RM0440, COMP
/// chapter; `COMP_INPUT_MINUS_DAC3_CH1` ... in `stm32g4xx_hal_comp.h`). DAC3 and DAC4 are
/// the G474's internal-only DACs. Returns (DAC 3 or 4, channel 1 or 2); `None` for no such
/// comparator.
pub const fn comp_dac(comp: u8) -> Option<(u8, u8)> {
    match comp {
        1 | 3 => Some((3, 1)),
        2 | 4 => Some((3, 2)),
        5 | 7 => Some((4, 1)),
        6 => Some((4, 2)),
        _ => None,
    }
}

/// COMPx_CSR.INMSEL for the DAC3/DAC4 channel of [`comp_dac`].
pub const COMP_INMSEL_DAC34: u32 = 0b100;

/// A comparator threshold: the DAC code and the output polarity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ComparatorThreshold {
    /// The 12-bit DAC code (DAC_DHR12Rx) of the amplifier output at the trip current.
    pub dac_counts: u16,
    /// COMPx_CSR.POL: the amplifier output falls with the current into the motor, so the
    /// comparator output (high when the input is above the DAC) is inverted.
    pub inverted: bool,
}

/// The DAC code and polarity at which a comparator on an amplifier output of `stage` fires
/// for a current of `trip_a` A into the motor: the amplifier's output there is
/// `bias + current_sign * gain * shunt * trip_a` V, in DAC counts of the same reference
/// (the DAC and the ADC share VREF+). `Err` names what does not fit: a trip that is not a
/// positive number, or one whose output voltage lies outside the DAC's range (the
/// amplifier saturates before the trip; or its output never reaches the code).
pub const fn comparator_threshold(
    stage: &PowerStage,
    trip_a: f32,
) -> Result<ComparatorThreshold, &'static str> {
    if !(trip_a > 0.0 && trip_a < f32::INFINITY) {
        return Err("the hardware trip level must be a positive current");
    }
    let volts = stage.amplifier_bias_v
        + stage.current_sign * stage.amplifier_gain * stage.shunt_ohm * trip_a;
    let counts = volts / stage.adc_vref * stage.adc_counts as f32;
    // strictly inside the code range: 0 and full scale cannot be crossed
    if !(counts >= 1.0 && counts <= stage.adc_counts as f32 - 2.0) {
        return Err("the hardware trip level is beyond the current-sense amplifier's range");
    }
    Ok(ComparatorThreshold {
        dac_counts: (counts + 0.5) as u16,
        inverted: stage.current_sign < 0.0,
    })
}

/// The board's ratings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ratings {
    /// Lowest DC bus the board runs from (its drivers' under-voltage lockout), V.
    pub bus_min_v: f32,
    /// Highest DC bus, V.
    pub bus_max_v: f32,
    /// Highest phase current, A peak.
    pub current_peak_a: f32,
}

/// A power board on the NUCLEO-G474RE.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardProfile {
    /// Short name (the `acim-firmware` feature, or `generic`).
    pub key: &'static str,
    /// The gate inputs.
    pub gates: Gates,
    /// The fault input.
    pub fault: Fault,
    /// The ADC channel plan.
    pub adc: AdcPlan,
    /// The measurement chain (shunts, amplifier gain and bias, bus divider).
    pub stage: PowerStage,
    /// The ratings.
    pub ratings: Ratings,
    /// The default bus profile (window, limits, trips).
    pub bus: BusProfile,
    /// The first-power-up profile (`--features low-voltage`, `defaults low-voltage`).
    pub low_voltage: BusProfile,
    /// The hardware over-current path, where the board routes the amplifier outputs to
    /// comparator inputs; `None`: the software trip only (say why in the profile's
    /// documentation).
    pub hardware_trip: Option<HardwareTrip>,
}

/// Pins the firmware uses for itself: USART2 TX (PA2, output) and RX (PA3, input), LD2
/// (PA5, output).
const UART_TX: Pin = pa(2);
const UART_RX: Pin = pa(3);
const LED: Pin = pa(5);

/// The G474's ADC channel of `pin` on ADC1 (`adc` = 1) or ADC2 (2), for the pins a profile
/// may use (RM0440 / datasheet pin tables); `None` where the pin is not an input of it.
pub const fn adc_channel(adc: u8, pin: Pin) -> Option<u8> {
    let table: [(Pin, u8, u8); 8] = [
        // (pin, ADC1 channel, ADC2 channel; 0: none)
        (pa(0), 1, 1),
        (pa(1), 2, 2),
        (pa(6), 0, 3),
        (pa(7), 0, 4),
        (pc(0), 6, 6),
        (pc(1), 7, 7),
        (pb(0), 15, 0),
        (pb(1), 12, 0),
    ];
    let mut i = 0;
    while i < table.len() {
        if table[i].0.is(pin) {
            let c = if adc == 1 { table[i].1 } else { table[i].2 };
            return if c == 0 { None } else { Some(c) };
        }
        i += 1;
    }
    None
}

/// The TIM1 complementary output pins of channel `ch` (0..3) at AF6, or AF4 for PB15.
const fn is_tim1_chn(ch: usize, pin: Pin) -> bool {
    let options: [[Pin; 2]; 3] = [[pa(7), pb(13)], [pb(0), pb(14)], [pb(1), pb(15)]];
    options[ch][0].is(pin) || options[ch][1].is(pin)
}

const fn contains(list: &[Pin], pin: Pin) -> bool {
    let mut i = 0;
    while i < list.len() {
        if list[i].is(pin) {
            return true;
        }
        i += 1;
    }
    false
}

impl BoardProfile {
    /// The output pins: gate inputs, enables, the UART's TX and the LED.
    pub const fn outputs(&self) -> [Option<Pin>; 11] {
        let g = &self.gates;
        let mut out = [None; 11];
        out[0] = Some(g.high_side[0]);
        out[1] = Some(g.high_side[1]);
        out[2] = Some(g.high_side[2]);
        let lows = match g.drive {
            GateDrive::Complementary { low_side, .. } => low_side,
            GateDrive::InputEnable { enable } => enable,
        };
        out[3] = Some(lows[0]);
        out[4] = Some(lows[1]);
        out[5] = Some(lows[2]);
        out[6] = Some(UART_TX);
        out[7] = Some(LED);
        out
    }

    /// The sense inputs: the four ADC pins, the fault input and the UART's RX.
    pub const fn inputs(&self) -> [Pin; 6] {
        let a = &self.adc;
        [
            a.adc1[0].pin,
            a.adc1[1].pin,
            a.adc2[0].pin,
            a.adc2[1].pin,
            self.fault.pin,
            UART_RX,
        ]
    }

    /// Whether the four ADC inputs are exactly `pins` (in any order).
    pub const fn senses_on(&self, pins: [Pin; 4]) -> bool {
        let ins = self.inputs();
        let mut i = 0;
        while i < 4 {
            let mut j = 0;
            let mut found = false;
            while j < 4 {
                found |= ins[j].is(pins[i]);
                j += 1;
            }
            if !found {
                return false;
            }
            i += 1;
        }
        true
    }

    /// The compile-time rules of a profile; `Err` names the broken one. Evaluated for
    /// every profile in a `const` item, so a broken profile does not build.
    pub const fn check(&self) -> Result<(), &'static str> {
        let g = &self.gates;
        // TIM1 CH1..3 on PA8..10 (the HAL's set-up takes these pins)
        if !(g.high_side[0].is(pa(8)) && g.high_side[1].is(pa(9)) && g.high_side[2].is(pa(10))) {
            return Err("the high-side inputs must be TIM1_CH1..3 on PA8, PA9, PA10");
        }
        if let GateDrive::Complementary { low_side, .. } = g.drive {
            let mut ch = 0;
            while ch < 3 {
                if !is_tim1_chn(ch, low_side[ch]) {
                    return Err("a low-side input is not a TIM1_CHxN pin of its channel");
                }
                ch += 1;
            }
        }
        // no output pin is a sense input, and no pin drives two outputs
        let outs = self.outputs();
        let ins = self.inputs();
        let mut i = 0;
        while i < outs.len() {
            if let Some(p) = outs[i] {
                if contains(&ins, p) {
                    return Err("an output pin is also a sense input");
                }
                let mut j = i + 1;
                while j < outs.len() {
                    if let Some(q) = outs[j] {
                        if p.is(q) {
                            return Err("a pin drives two outputs");
                        }
                    }
                    j += 1;
                }
            }
            i += 1;
        }
        // no pin is sensed twice
        let mut i = 0;
        while i < ins.len() {
            let mut j = i + 1;
            while j < ins.len() {
                if ins[i].is(ins[j]) {
                    return Err("a pin is sensed twice");
                }
                j += 1;
            }
            i += 1;
        }
        // the fault line on a TIM1_BKIN pin (AF6)
        if !(self.fault.pin.is(pa(6)) || self.fault.pin.is(pb(12))) {
            return Err("the fault input must be TIM1_BKIN (PA6 or PB12)");
        }
        if self.fault.filter > 15 {
            return Err("the break filter is a 4-bit code");
        }
        // the ADC plan: each channel exists on its ADC, each signal once
        let a = &self.adc;
        let mut r = 0;
        while r < 2 {
            match adc_channel(1, a.adc1[r].pin) {
                Some(c) if c == a.adc1[r].channel => {}
                _ => return Err("an ADC1 rank's channel is not its pin's ADC1 channel"),
            }
            match adc_channel(2, a.adc2[r].pin) {
                Some(c) if c == a.adc2[r].channel => {}
                _ => return Err("an ADC2 rank's channel is not its pin's ADC2 channel"),
            }
            r += 1;
        }
        let order = [a.adc1[0], a.adc2[0], a.adc2[1], a.adc1[1]];
        let mut seen = 0u8;
        let mut k = 0;
        while k < 4 {
            seen |= 1 << order[k].signal as u8;
            k += 1;
        }
        if seen != 0b1111 {
            return Err("the ADC plan must carry U, V, W and the bus once each");
        }
        if self.stage.shunts != 3 {
            return Err("the ADC plan measures three phase currents");
        }
        // the measurement chain covers the bus and current ranges, within the ratings
        let mut p = 0;
        while p < 2 {
            let bus = if p == 0 { &self.bus } else { &self.low_voltage };
            if bus.dc_bus_max > 0.95 * self.stage.bus_full_scale() {
                return Err("a bus profile's maximum is beyond 95 % of the divider's full scale");
            }
            if bus.dc_bus_max > self.ratings.bus_max_v || bus.dc_bus_min < self.ratings.bus_min_v {
                return Err("a bus profile's window is outside the board's rating");
            }
            if bus.overcurrent_trip > 0.9 * self.stage.current_full_scale() {
                return Err("a bus profile's trip is beyond 90 % of the current-sense full scale");
            }
            if bus.current_limit > self.ratings.current_peak_a
                || bus.overcurrent_trip > 1.5 * self.ratings.current_peak_a
            {
                return Err("a bus profile's current is beyond the board's rating");
            }
            p += 1;
        }
        // the hardware trip: each comparator on the pin of its signal, once each, its
        // threshold inside the DAC's range for both bus profiles' trips
        if let Some(h) = self.hardware_trip {
            if h.filter > 15 {
                return Err("the break-2 filter is a 4-bit code");
            }
            let cs = h.comparators;
            let mut i = 0;
            while i < cs.len() {
                let c = cs[i];
                let pin = match comp_input_pin(c.comp, c.io2) {
                    Some(pin) => pin,
                    None => return Err("a comparator input that the G474 does not have"),
                };
                let order = [a.adc1[0], a.adc2[0], a.adc2[1], a.adc1[1]];
                let sensed = order[a.slot(c.signal)].pin;
                if !pin.is(sensed) || c.signal as u8 == Signal::Bus as u8 {
                    return Err("a comparator is not on its phase current's amplifier pin");
                }
                let mut j = i + 1;
                while j < cs.len() {
                    if cs[j].comp == c.comp || cs[j].signal as u8 == c.signal as u8 {
                        return Err("a comparator or a phase is used twice");
                    }
                    j += 1;
                }
                i += 1;
            }
            if cs.is_empty() || cs.len() > 3 {
                return Err("a hardware trip has one to three comparators");
            }
            let mut p = 0;
            while p < 2 {
                let bus = if p == 0 { &self.bus } else { &self.low_voltage };
                let level = acim::hardware_trip::HARDWARE_TRIP_RATIO * bus.overcurrent_trip;
                if comparator_threshold(&self.stage, level).is_err() {
                    return Err("a bus profile's hardware trip is beyond the amplifier's range");
                }
                p += 1;
            }
        }
        Ok(())
    }
}

/// Fails the build with the broken rule.
const fn must_pass(p: &BoardProfile) {
    if let Err(e) = p.check() {
        panic!("{}", e)
    }
}

const _: () = must_pass(&GENERIC);
const _: () = must_pass(&X_NUCLEO_IHM16M1);
const _: () = must_pass(&STEVAL_IHM023V3);

/// The generic stage's ADC plan: ADC1 = U current (PA0, IN1), bus (PC0, IN6); ADC2 = V
/// current (PC1, IN7), W current (PA1, IN2).
const GENERIC_ADC: AdcPlan = AdcPlan {
    adc1: [
        AdcInput {
            pin: pa(0),
            channel: 1,
            signal: Signal::CurrentU,
        },
        AdcInput {
            pin: pc(0),
            channel: 6,
            signal: Signal::Bus,
        },
    ],
    adc2: [
        AdcInput {
            pin: pc(1),
            channel: 7,
            signal: Signal::CurrentV,
        },
        AdcInput {
            pin: pa(1),
            channel: 2,
            signal: Signal::CurrentW,
        },
    ],
};

/// The generic three-shunt IGBT inverter for 230 VAC mains (what the firmware has always
/// assumed; the default build): active-high gate inputs with pull-downs, complementary
/// TIM1 outputs (low sides on PA7, PB0, PB1), fault on PA6, the measurement chain of
/// [`crate::board`]'s module documentation.
pub const GENERIC: BoardProfile = BoardProfile {
    key: "generic",
    gates: Gates {
        high_side: [pa(8), pa(9), pa(10)],
        high_active_low: false,
        drive: GateDrive::Complementary {
            low_side: [pa(7), pb(0), pb(1)],
            low_active_low: false,
        },
    },
    fault: Fault {
        pin: pa(6),
        active_low: true,
        filter: 0b1000,
    },
    adc: GENERIC_ADC,
    stage: PowerStage {
        name: "generic 3-shunt IGBT inverter, 230 VAC / 325 VDC (STEVAL-IHM028V2 class), values unverified",
        shunts: 3,
        shunt_ohm: 0.033,
        amplifier_gain: 5.0,
        amplifier_bias_v: 1.65,
        current_sign: -1.0,
        divider_top_ohm: 990_000.0,
        divider_bottom_ohm: 6_800.0,
        adc_vref: 3.3,
        adc_counts: 4096,
    },
    ratings: Ratings {
        bus_min_v: 10.0,
        bus_max_v: 400.0,
        current_peak_a: 8.0,
    },
    bus: MAINS,
    low_voltage: LOW_VOLTAGE,
    hardware_trip: Some(GENERIC_HARDWARE_TRIP),
};

/// The generic plan's comparators: U on PA0 is COMP3's IO1, W on PA1 COMP1's IO1, both
/// against DAC3 CH1; V on PC1 reaches only COMP3 (IO2), which U takes, so V is watched
/// by the software trip alone (with three phases summing to zero, a runaway of V drives
/// U or W the other way). Break-2 filter fDTS/32, N = 5: 0.94 us at 170 MHz (RM0440
/// section 29, TIMx_BDTR.BK2F), against the switching spikes the amplifiers pass.
const GENERIC_HARDWARE_TRIP: HardwareTrip = HardwareTrip {
    comparators: &[
        SenseComparator {
            comp: 3,
            io2: false,
            signal: Signal::CurrentU,
        },
        SenseComparator {
            comp: 1,
            io2: false,
            signal: Signal::CurrentW,
        },
    ],
    filter: 0b1101,
};

/// The X-NUCLEO-IHM16M1's bus window: its 7-45 V rating, within the 4:1 window the
/// settings allow; the current within its 1.5 A rms (2.1 A peak) rating, above the paper
/// machine's 1.5 A flux current, the trip within the sense range (3.3 A).
const IHM16M1_BUS: BusProfile = BusProfile {
    name: "X-NUCLEO-IHM16M1 12-45 V",
    dc_bus_min: 12.0,
    dc_bus_max: 45.0,
    current_limit: 2.0,
    overcurrent_trip: 2.9,
    max_speed_rpm: 300.0,
};

/// ST X-NUCLEO-IHM16M1 (STSPIN830, 7-45 V, 1.5 A rms), three-shunt configuration, on the
/// NUCLEO's Arduino/Morpho headers: phase inputs IN1..3 on PA8, PA9, PA10 (TIM1 CH1..3,
/// no complementary outputs: the STSPIN830 makes its own dead time), phase enables
/// EN1..3 on PB13, PB14, PB15 (GPIO outputs: low while the outputs are off), EN_FAULT on
/// PB12 (TIM1_BKIN, open drain, active low), currents U, V, W on PA1, PB1, PB0 and the bus
/// on PA0. PB0/PB1 are ADC1-only inputs, so ADC1 takes V and W, ADC2 takes U and the bus.
/// Scaling: 0.33 ohm shunts, amplifier gain 1.53 (output falling for current into the
/// motor), the bias assumed at 1.65 V; bus divider 169 k / 9.31 k (63 V full scale).
pub const X_NUCLEO_IHM16M1: BoardProfile = BoardProfile {
    key: "x-nucleo-ihm16m1",
    gates: Gates {
        high_side: [pa(8), pa(9), pa(10)],
        high_active_low: false,
        drive: GateDrive::InputEnable {
            enable: [pb(13), pb(14), pb(15)],
        },
    },
    fault: Fault {
        pin: pb(12),
        active_low: true,
        filter: 0b1000,
    },
    adc: AdcPlan {
        adc1: [
            AdcInput {
                pin: pb(1),
                channel: 12,
                signal: Signal::CurrentV,
            },
            AdcInput {
                pin: pb(0),
                channel: 15,
                signal: Signal::CurrentW,
            },
        ],
        adc2: [
            AdcInput {
                pin: pa(1),
                channel: 2,
                signal: Signal::CurrentU,
            },
            AdcInput {
                pin: pa(0),
                channel: 1,
                signal: Signal::Bus,
            },
        ],
    },
    stage: PowerStage {
        name: "X-NUCLEO-IHM16M1 (STSPIN830, 3 shunts), 7-45 V, values to be checked against UM2415",
        shunts: 3,
        shunt_ohm: 0.33,
        amplifier_gain: 1.53,
        amplifier_bias_v: 1.65,
        current_sign: -1.0,
        divider_top_ohm: 169_000.0,
        divider_bottom_ohm: 9_310.0,
        adc_vref: 3.3,
        adc_counts: 4096,
    },
    ratings: Ratings {
        bus_min_v: 7.0,
        bus_max_v: 45.0,
        current_peak_a: 2.1,
    },
    bus: IHM16M1_BUS,
    low_voltage: IHM16M1_BUS,
    // U on PA1 is COMP1's IO1 (DAC3 CH1), W on PB0 COMP4's IO1 (DAC3 CH2); V on PB1
    // reaches only COMP1 (IO2), which U takes. The STSPIN830's own over-current
    // comparator (EN_FAULT into BKIN) stays the first protection of this board.
    hardware_trip: Some(HardwareTrip {
        comparators: &[
            SenseComparator {
                comp: 1,
                io2: false,
                signal: Signal::CurrentU,
            },
            SenseComparator {
                comp: 4,
                io2: false,
                signal: Signal::CurrentW,
            },
        ],
        filter: 0b1101,
    }),
};

/// A three-phase IGBT stage with L6390 gate drivers (STEVAL-IHM023V3; the STEVAL-IHM028V2's
/// IPM has drivers of the same family: check its input table): HIN active high, **LIN
/// active low** (an internal pull-up: a floating LIN is off), so TIM1's low-side outputs
/// are inverted (CCxNP = 1) and idle high (OISxN = 1): "all gates low" would switch every
/// low side on. Pins and measurement chain as [`GENERIC`] (wire the board to them; check
/// its shunts, gains and divider).
pub const STEVAL_IHM023V3: BoardProfile = BoardProfile {
    key: "steval-ihm023v3",
    gates: Gates {
        high_side: [pa(8), pa(9), pa(10)],
        high_active_low: false,
        drive: GateDrive::Complementary {
            low_side: [pa(7), pb(0), pb(1)],
            low_active_low: true,
        },
    },
    fault: Fault {
        pin: pa(6),
        active_low: true,
        filter: 0b1000,
    },
    adc: GENERIC_ADC,
    stage: PowerStage {
        name: "L6390 IGBT inverter (STEVAL-IHM023V3 class), LIN active low, values unverified",
        ..GENERIC.stage
    },
    ratings: Ratings {
        bus_min_v: 10.0,
        bus_max_v: 400.0,
        current_peak_a: 8.0,
    },
    bus: MAINS,
    low_voltage: LOW_VOLTAGE,
    // the generic stage's pins, so its comparators
    hardware_trip: Some(GENERIC_HARDWARE_TRIP),
};

/// Every profile, the default first.
pub const ALL: [BoardProfile; 3] = [GENERIC, X_NUCLEO_IHM16M1, STEVAL_IHM023V3];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::drive_config_with;
    use acim::Drive;

    #[test]
    fn every_profile_passes_its_checks_and_builds_a_drive() {
        for p in ALL {
            assert_eq!(p.check(), Ok(()), "{}", p.key);
            for bus in [p.bus, p.low_voltage] {
                let cfg = drive_config_with(&p, &bus);
                assert!(Drive::new(cfg).is_ok(), "{} {}", p.key, bus.name);
            }
        }
    }

    /// Each rule refuses what it names.
    #[test]
    fn broken_profiles_are_refused() {
        let mut p = GENERIC;
        p.adc.adc1[0].pin = pa(7);
        p.adc.adc1[0].channel = 0;
        assert!(p.check().is_err());
        // a low-side output driving a sense input (the review's IHM16M1 finding: PB0/PB1
        // as CH2N/CH3N into the board's amplifier outputs)
        let mut p = X_NUCLEO_IHM16M1;
        p.gates.drive = GENERIC.gates.drive;
        assert_eq!(p.check(), Err("an output pin is also a sense input"));
        // a channel that is not the pin's on that ADC
        let mut p = GENERIC;
        p.adc.adc2[0].channel = 6;
        assert_eq!(
            p.check(),
            Err("an ADC2 rank's channel is not its pin's ADC2 channel")
        );
        // PB0 has no ADC2 channel
        let mut p = X_NUCLEO_IHM16M1;
        p.adc.adc2[0].pin = pb(0);
        assert!(p.check().is_err());
        // the bus window beyond the divider (the mains profile on the IHM16M1's divider)
        let mut p = X_NUCLEO_IHM16M1;
        p.bus = MAINS;
        assert_eq!(
            p.check(),
            Err("a bus profile's maximum is beyond 95 % of the divider's full scale")
        );
        // a trip beyond the current-sense range
        let mut p = X_NUCLEO_IHM16M1;
        p.bus.overcurrent_trip = 3.2;
        assert_eq!(
            p.check(),
            Err("a bus profile's trip is beyond 90 % of the current-sense full scale")
        );
        let mut p = GENERIC;
        p.fault.pin = pb(13);
        assert!(p.check().is_err());
        let mut p = GENERIC;
        p.adc.adc1[1].signal = Signal::CurrentU;
        assert_eq!(
            p.check(),
            Err("the ADC plan must carry U, V, W and the bus once each")
        );
    }

    /// The comparator threshold from the measurement chain: the generic stage (0.033 ohm,
    /// gain 5, bias 1.65 V, output falling with the motor current) at its 8 A trip sits at
    /// 1.65 - 8 * 0.165 = 0.33 V, 409.6 counts of 3.3 V / 4096, and the comparator output
    /// is inverted; the IHM16M1 (0.33 ohm, gain 1.53) at 2.9 A at 1.65 - 1.464 = 0.186 V,
    /// 230.6 counts. Beyond the amplifier's range, or not a current, is refused.
    #[test]
    fn comparator_thresholds_follow_the_measurement_chain() {
        let t = comparator_threshold(&GENERIC.stage, 8.0).unwrap();
        assert_eq!(
            t,
            ComparatorThreshold {
                dac_counts: 410,
                inverted: true
            }
        );
        let t = comparator_threshold(&X_NUCLEO_IHM16M1.stage, 2.9).unwrap();
        assert_eq!(t.dac_counts, 231);
        assert!(t.inverted);
        // a rising amplifier: the same distance above the bias, not inverted
        let mut up = GENERIC.stage;
        up.current_sign = 1.0;
        let t = comparator_threshold(&up, 8.0).unwrap();
        assert_eq!(t.dac_counts, 3686);
        assert!(!t.inverted);
        // the amplifier saturates at 1.65 / 0.165 = 10 A
        assert!(comparator_threshold(&GENERIC.stage, 10.5).is_err());
        assert!(comparator_threshold(&GENERIC.stage, 0.0).is_err());
        assert!(comparator_threshold(&GENERIC.stage, f32::NAN).is_err());
        // the design's level: the drive's trip (acim::hardware_trip)
        let cfg = drive_config_with(&GENERIC, &GENERIC.bus);
        let level = acim::hardware_trip::hardware_trip_level(&cfg);
        assert_eq!(level, GENERIC.bus.overcurrent_trip);
    }

    /// The comparator inputs as RM0440 assigns them, and the profiles' comparators on
    /// their signals' pins.
    #[test]
    fn comparators_sit_on_their_amplifier_pins() {
        assert_eq!(comp_input_pin(3, false), Some(pa(0)));
        assert_eq!(comp_input_pin(3, true), Some(pc(1)));
        assert_eq!(comp_input_pin(1, false), Some(pa(1)));
        assert_eq!(comp_input_pin(4, false), Some(pb(0)));
        assert_eq!(comp_input_pin(8, false), None);
        assert_eq!(comp_dac(1), Some((3, 1)));
        assert_eq!(comp_dac(4), Some((3, 2)));
        assert_eq!(comp_dac(6), Some((4, 2)));
        for p in ALL {
            let h = p.hardware_trip.expect("every profile routes its currents");
            assert_eq!(h.comparators.len(), 2, "{}", p.key);
        }
        // the generic comparators share DAC3 CH1; the IHM16M1's use both DAC3 channels
        assert_eq!(
            GENERIC_HARDWARE_TRIP.dac_channels(),
            [Some((3, 1)), None, None]
        );
        let h = X_NUCLEO_IHM16M1.hardware_trip.unwrap();
        assert_eq!(h.dac_channels(), [Some((3, 1)), Some((3, 2)), None]);
        // a comparator on the wrong pin, or twice, is refused
        let mut p = GENERIC;
        p.hardware_trip = Some(HardwareTrip {
            comparators: &[SenseComparator {
                comp: 3,
                io2: true,
                signal: Signal::CurrentU,
            }],
            filter: 0,
        });
        assert_eq!(
            p.check(),
            Err("a comparator is not on its phase current's amplifier pin")
        );
        p.hardware_trip = Some(HardwareTrip {
            comparators: &[
                SenseComparator {
                    comp: 3,
                    io2: false,
                    signal: Signal::CurrentU,
                },
                SenseComparator {
                    comp: 3,
                    io2: false,
                    signal: Signal::CurrentU,
                },
            ],
            filter: 0,
        });
        assert_eq!(p.check(), Err("a comparator or a phase is used twice"));
        // a trip beyond the amplifier's range
        let mut p = GENERIC;
        p.hardware_trip = Some(GENERIC_HARDWARE_TRIP);
        p.stage.amplifier_gain = 9.0;
        assert!(p.check().is_err());
        // no hardware trip: the software path only, allowed
        let mut p = GENERIC;
        p.hardware_trip = None;
        assert_eq!(p.check(), Ok(()));
    }

    /// The L6390 stage inverts and idles its low sides high; the others drive no
    /// inverted output; the IHM16M1 has enables and no complementary outputs.
    #[test]
    fn polarity_and_idle_levels() {
        assert_eq!(GENERIC.gates.ccer_polarity(), 0);
        assert_eq!(GENERIC.gates.idle_bits(), 0);
        assert_eq!(
            STEVAL_IHM023V3.gates.ccer_polarity(),
            (1 << 3) | (1 << 7) | (1 << 11)
        );
        assert_eq!(
            STEVAL_IHM023V3.gates.idle_bits(),
            (1 << 9) | (1 << 11) | (1 << 13)
        );
        assert_eq!(X_NUCLEO_IHM16M1.gates.idle_bits(), 0);
        assert!(!X_NUCLEO_IHM16M1.gates.complementary());
        assert_eq!(
            X_NUCLEO_IHM16M1.gates.enable(),
            Some([pb(13), pb(14), pb(15)])
        );
    }

    /// The read order's slots: the generic plan is the identity (the firmware's read of
    /// ADC1 rank 1, ADC2 ranks 1 and 2, ADC1 rank 2 as U, V, W, bus, as before).
    #[test]
    fn adc_slots() {
        let g = GENERIC.adc;
        assert_eq!(
            [
                g.slot(Signal::CurrentU),
                g.slot(Signal::CurrentV),
                g.slot(Signal::CurrentW),
                g.slot(Signal::Bus)
            ],
            [0, 1, 2, 3]
        );
        assert_eq!(g.bus(), (6, 1));
        let h = X_NUCLEO_IHM16M1.adc;
        assert_eq!(
            [
                h.slot(Signal::CurrentU),
                h.slot(Signal::CurrentV),
                h.slot(Signal::CurrentW),
                h.slot(Signal::Bus)
            ],
            [1, 0, 3, 2]
        );
        assert_eq!(h.bus(), (1, 2));
        // 48 V on the IHM16M1 reads as 48 V (the review: 367 V with the generic scaling)
        let s = X_NUCLEO_IHM16M1.stage;
        assert!((s.bus_full_scale() - 63.2).abs() < 0.1);
        assert!((1.0 / s.amps_per_count().abs() - 626.7).abs() < 0.5);
    }
}
