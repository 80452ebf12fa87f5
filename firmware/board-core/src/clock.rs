//! The core clock judged from the hardware registers after set-up, not from the value the
//! HAL computed (firmware review D2: with the PWR bus clock off, the boost-mode write can
//! be dropped and the core then runs 170 MHz in Range 1 normal mode, rated 150 MHz, while
//! the computed clock still says 170 MHz).
//!
//! Register fields (RM0440): RCC_PLLCFGR PLLSRC\[1:0\] (2 = HSI16), PLLM\[7:4\] (M - 1),
//! PLLN\[14:8\], PLLREN bit 24, PLLR\[26:25\] (/2, /4, /6, /8); RCC_CFGR SWS\[3:2\]
//! (3 = PLL), HPRE\[7:4\] (0xxx = /1); FLASH_ACR LATENCY\[3:0\]; PWR_CR1 VOS\[10:9\]
//! (1 = Range 1); PWR_CR5 R1MODE bit 8 (0 = boost).

/// The registers read back after the clock set-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockRegisters {
    /// RCC_CFGR.
    pub rcc_cfgr: u32,
    /// RCC_PLLCFGR.
    pub rcc_pllcfgr: u32,
    /// FLASH_ACR.
    pub flash_acr: u32,
    /// PWR_CR1.
    pub pwr_cr1: u32,
    /// PWR_CR5.
    pub pwr_cr5: u32,
}

/// Why the clock is not what the firmware needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockError {
    /// The system clock is not the PLL (RCC_CFGR.SWS).
    NotOnPll,
    /// The PLL does not run from HSI16 or its R output is off.
    PllSetup,
    /// The AHB prescaler is not /1 (HCLK != SYSCLK).
    AhbPrescaler,
    /// Not Range 1 boost mode (PWR_CR1.VOS, PWR_CR5.R1MODE): above 150 MHz it is required.
    NotBoost,
    /// Flash wait states below what the frequency needs (FLASH_ACR.LATENCY).
    FlashLatency(u8),
    /// The PLL gives another frequency, Hz.
    Frequency(u32),
}

const HSI16_HZ: u32 = 16_000_000;

/// Checks the read-back registers against `expected_hz`; returns the frequency from the
/// PLL fields. Needs 4 wait states at 136-170 MHz in boost mode (RM0440, flash latency).
pub fn check(r: &ClockRegisters, expected_hz: u32) -> Result<u32, ClockError> {
    if (r.rcc_cfgr >> 2) & 0b11 != 0b11 {
        return Err(ClockError::NotOnPll);
    }
    let p = r.rcc_pllcfgr;
    if p & 0b11 != 0b10 || (p >> 24) & 1 == 0 {
        return Err(ClockError::PllSetup);
    }
    if (r.rcc_cfgr >> 7) & 1 != 0 {
        return Err(ClockError::AhbPrescaler);
    }
    let m = ((p >> 4) & 0xF) + 1;
    let n = (p >> 8) & 0x7F;
    let div_r = 2 * (((p >> 25) & 0b11) + 1);
    let hz = (HSI16_HZ / m) * n / div_r;
    if (r.pwr_cr1 >> 9) & 0b11 != 0b01 || (r.pwr_cr5 >> 8) & 1 != 0 {
        return Err(ClockError::NotBoost);
    }
    let latency = (r.flash_acr & 0xF) as u8;
    if hz > 136_000_000 && latency < 4 {
        return Err(ClockError::FlashLatency(latency));
    }
    if hz != expected_hz {
        return Err(ClockError::Frequency(hz));
    }
    Ok(hz)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The register values the review read off the emulated boot (PLLCFGR 0x0100_5532).
    fn good() -> ClockRegisters {
        ClockRegisters {
            rcc_cfgr: 0b1111,
            rcc_pllcfgr: 0x0100_5532,
            flash_acr: 0x0000_0604,
            pwr_cr1: 0x0000_0200,
            pwr_cr5: 0x0000_0000,
        }
    }

    #[test]
    fn the_intended_set_up_is_170_mhz_boost() {
        assert_eq!(check(&good(), 170_000_000), Ok(170_000_000));
    }

    /// D2: the boost write dropped because the PWR clock was off leaves R1MODE at its
    /// reset value 1; a gated PWR reads as 0 (VOS = 0). Both are refused.
    #[test]
    fn a_dropped_boost_write_is_caught() {
        let mut r = good();
        r.pwr_cr5 = 1 << 8;
        assert_eq!(check(&r, 170_000_000), Err(ClockError::NotBoost));
        let mut r = good();
        r.pwr_cr1 = 0;
        r.pwr_cr5 = 0;
        assert_eq!(check(&r, 170_000_000), Err(ClockError::NotBoost));
    }

    #[test]
    fn wrong_latency_source_or_frequency_is_caught() {
        let mut r = good();
        r.flash_acr = 0x603;
        assert_eq!(check(&r, 170_000_000), Err(ClockError::FlashLatency(3)));
        let mut r = good();
        r.rcc_cfgr = 0b0101; // running from HSI16
        assert_eq!(check(&r, 170_000_000), Err(ClockError::NotOnPll));
        let mut r = good();
        r.rcc_pllcfgr = 0x0100_5032; // N = 80: 160 MHz
        assert_eq!(
            check(&r, 170_000_000),
            Err(ClockError::Frequency(160_000_000))
        );
        let mut r = good();
        r.rcc_pllcfgr &= !(1 << 24); // R output off
        assert_eq!(check(&r, 170_000_000), Err(ClockError::PllSetup));
    }
}
