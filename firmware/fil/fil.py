#!/usr/bin/env python3
"""Firmware in the loop: the unmodified firmware ELF on an emulated Cortex-M4F.

The Unicorn engine executes the firmware's instructions; this module models the
peripherals the firmware touches, from RM0440 (STM32G4 reference manual), at register
level:

- RCC (clock enables, HSI/PLL ready bits, SWS follows SW), PWR (reads 0 and drops writes
  while RCC_APB1ENR1.PWREN is clear, as a gated bus does), FLASH_ACR;
- GPIO (plain registers), DBGMCU, SYSCFG;
- TIM1: registers, compare values, MOE/BIF/B2IF/SBIF (a break clears MOE and sets the
  flag; MOE cannot be set while a break input is active), rc_w0 status flags;
- ADC1/ADC2: power-up (ADCAL self-clears, ADRDY on ADEN), injected conversions triggered
  each PWM period once JADSTART is set (JEOS/JEOC, rc_w1), JDRx from a load model through
  the board's shunt/amplifier/divider description;
- COMP1..7 (plain registers) and the internal DAC3/DAC4 (plain registers; DAC_SR.DACxRDY
  reads set once DAC_CR.ENx is), configured for the hardware over-current path into
  TIM1's break 2 (their analog behaviour is not modelled: a comparator never fires);
- CORDIC (sine and cosine of the q1.31 argument), IWDG (start/feed counted), USART2 (bytes
  in and out), SysTick (COUNTFLAG reads set: delays take no emulated time), DWT (CYCCNT =
  instructions executed), NVIC (enables; software pends, whose interrupt runs after the
  control interrupt returns), TIM6 (the self-test's period interrupt).

Time: the main program runs in chunks of instructions; one PWM period is
`INSTRUCTIONS_PER_PERIOD` instructions of it (8 000; the real period is 34 000 cycles at
170 MHz, of which the main loop only polls). At each period boundary the conversions complete and, if enabled and not
masked by PRIMASK, the control interrupt runs to its return (its own instructions do not
advance time). Exception entry is done here: the context is saved, 104 bytes of frame are
reserved on the stack, LR points at a stop address, and the context is restored when the
handler returns there.

What it does not model: cycle timing (wait states, pipeline, the real ADC conversion time),
the update-event instant of TIM1, analog behaviour, DMA, and any peripheral the firmware
does not use.
"""
import math
import struct

from unicorn import (Uc, UC_ARCH_ARM, UC_MODE_THUMB, UC_MODE_MCLASS, UC_HOOK_BLOCK,
                     UC_HOOK_CODE, UC_HOOK_MEM_READ, UC_HOOK_MEM_WRITE, UcError)
from unicorn.arm_const import (
    UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R4,
    UC_ARM_REG_R5, UC_ARM_REG_R6, UC_ARM_REG_R7, UC_ARM_REG_R8, UC_ARM_REG_R9,
    UC_ARM_REG_R10, UC_ARM_REG_R11, UC_ARM_REG_R12, UC_ARM_REG_SP, UC_ARM_REG_LR,
    UC_ARM_REG_PC, UC_ARM_REG_XPSR, UC_ARM_REG_PRIMASK, UC_ARM_REG_FPSCR, UC_ARM_REG_S0,
    UC_CPU_ARM_CORTEX_M4,
)

try:
    # the library and callback types of the binding (unicorn 2.1.1, pinned): see
    # Machine._map_peripherals
    from unicorn.unicorn_py3.unicorn import (uclib as _uclib, MMIO_READ_CFUNC as _MMIO_READ_CFUNC,
                                             MMIO_WRITE_CFUNC as _MMIO_WRITE_CFUNC)
except ImportError:
    _uclib = None


def _keep_exception(uc, e):
    # what the binding's own callback guard does: the first exception is raised by
    # emu_start once the emulation has stopped
    if uc._hook_exception is None:
        uc._hook_exception = e
    uc.emu_stop()


# main-program instructions per PWM period: the real budget is 34 000 cycles, of which
# the main loop only polls; 8 000 keeps the emulation fast and is ample for its work
INSTRUCTIONS_PER_PERIOD = 8_000
STOP = 0x0FFF_0000          # handlers "return" here (mapped, never executed)
ADC1_2_IRQ = 18
SLOW_TASK_IRQ = 101   # FMAC's vector: the firmware's slow task, pended by software
TIM6_IRQ = 54
NMI_VECTOR = 2
HARDFAULT_VECTOR = 3

# board description (firmware/board-core/src/board.rs, POWER_STAGE)
SHUNT_OHM, AMP_GAIN, AMP_BIAS_V, CURRENT_SIGN = 0.033, 5.0, 1.65, -1.0
DIV_TOP, DIV_BOTTOM, VREF, COUNTS = 990_000.0, 6_800.0, 3.3, 4096
# the board profiles' measurement chains and ADC channel plans (firmware/board-core/src/
# profile.rs): (ADC, channel) -> signal. The ADC model decodes the firmware's JSQR writes
# through this map, so a profile whose firmware programs the wrong channels reads nothing
# (0 counts: the offset calibration refuses it).
GENERIC_BOARD = dict(shunt=SHUNT_OHM, gain=AMP_GAIN, bias=AMP_BIAS_V, sign=CURRENT_SIGN,
                     top=DIV_TOP, bottom=DIV_BOTTOM,
                     channels={(1, 1): "U", (1, 6): "bus", (2, 7): "V", (2, 2): "W"})
BOARDS = {
    "generic": GENERIC_BOARD,
    "x-nucleo-ihm16m1": dict(shunt=0.33, gain=1.53, bias=1.65, sign=-1.0, top=169_000.0,
                             bottom=9_310.0,
                             channels={(2, 2): "U", (1, 12): "V", (1, 15): "W", (2, 1): "bus"}),
    "steval-ihm023v3": GENERIC_BOARD,
}

GPR = [UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R4,
       UC_ARM_REG_R5, UC_ARM_REG_R6, UC_ARM_REG_R7, UC_ARM_REG_R8, UC_ARM_REG_R9,
       UC_ARM_REG_R10, UC_ARM_REG_R11, UC_ARM_REG_R12, UC_ARM_REG_SP, UC_ARM_REG_LR,
       UC_ARM_REG_PC, UC_ARM_REG_XPSR, UC_ARM_REG_PRIMASK, UC_ARM_REG_FPSCR]
FPR = [UC_ARM_REG_S0 + i for i in range(32)]
# data registers: writing one only stores its value (SP, PC, xPSR, PRIMASK and FPSCR do more)
_PLAIN_REGS = frozenset(GPR[:13] + [UC_ARM_REG_LR])

DAC_REGS = {0x0: "CR", 0x8: "DHR12R1", 0x14: "DHR12R2", 0x34: "SR", 0x3C: "MCR"}
# peripheral bases and the register names the write log prints
PERIPHERALS = {
    0x4000_1000: ("TIM6", {0x0: "CR1", 0xC: "DIER", 0x10: "SR", 0x14: "EGR", 0x28: "PSC", 0x2C: "ARR"}),
    0x4000_3000: ("IWDG", {0x0: "KR", 0x4: "PR", 0x8: "RLR", 0xC: "SR", 0x10: "WINR"}),
    0x4000_4400: ("USART2", {0x0: "CR1", 0x4: "CR2", 0x8: "CR3", 0xC: "BRR", 0x18: "RQR",
                             0x20: "ICR", 0x28: "TDR", 0x2C: "PRESC"}),
    0x4000_7000: ("PWR", {0x0: "CR1", 0x4: "CR2", 0x8: "CR3", 0xC: "CR4", 0x18: "SCR", 0x80: "CR5"}),
    0x4001_0000: ("SYSCFG", {0x1C: "CFGR2"}),
    0x4001_0200: ("COMP", {0x0: "C1CSR", 0x4: "C2CSR", 0x8: "C3CSR", 0xC: "C4CSR",
                           0x10: "C5CSR", 0x14: "C6CSR", 0x18: "C7CSR"}),
    0x4001_2C00: ("TIM1", {0x0: "CR1", 0x4: "CR2", 0x8: "SMCR", 0xC: "DIER", 0x10: "SR",
                           0x14: "EGR", 0x18: "CCMR1", 0x1C: "CCMR2", 0x20: "CCER",
                           0x24: "CNT", 0x28: "PSC", 0x2C: "ARR", 0x30: "RCR", 0x34: "CCR1",
                           0x38: "CCR2", 0x3C: "CCR3", 0x40: "CCR4", 0x44: "BDTR",
                           0x48: "CCR5", 0x4C: "CCR6", 0x50: "CCMR3", 0x54: "DTR2",
                           0x58: "ECR", 0x5C: "TISEL", 0x60: "AF1", 0x64: "AF2", 0x68: "OR"}),
    0x4002_0C00: ("CORDIC", {0x0: "CSR", 0x4: "WDATA"}),
    0x4002_1000: ("RCC", {0x0: "CR", 0x4: "ICSCR", 0x8: "CFGR", 0xC: "PLLCFGR", 0x18: "CIER",
                          0x28: "AHB1RSTR", 0x2C: "AHB2RSTR", 0x30: "AHB3RSTR",
                          0x38: "APB1RSTR1", 0x3C: "APB1RSTR2", 0x40: "APB2RSTR",
                          0x20: "CICR", 0x48: "AHB1ENR", 0x4C: "AHB2ENR", 0x50: "AHB3ENR",
                          0x58: "APB1ENR1", 0x5C: "APB1ENR2", 0x60: "APB2ENR", 0x88: "CCIPR",
                          0x90: "BDCR", 0x94: "CSR", 0x9C: "CCIPR2"}),
    0x4002_2000: ("FLASH", {0x0: "ACR", 0x8: "KEYR", 0x10: "SR", 0x14: "CR", 0x18: "ECCR",
                            0x20: "OPTR"}),
    0x4800_0000: ("GPIOA", {}), 0x4800_0400: ("GPIOB", {}), 0x4800_0800: ("GPIOC", {}),
    0x5000_0000: ("ADC1", {}), 0x5000_0100: ("ADC2", {}), 0x5000_0300: ("ADC12", {0x8: "CCR"}),
    0x5000_1000: ("DAC3", DAC_REGS), 0x5000_1400: ("DAC4", DAC_REGS),
    0xE004_2000: ("DBGMCU", {0x4: "CR", 0x8: "APB1FZR1", 0xC: "APB1FZR2", 0x10: "APB2FZR"}),
}
GPIO_REGS = {0x0: "MODER", 0x4: "OTYPER", 0x8: "OSPEEDR", 0xC: "PUPDR", 0x14: "ODR",
             0x18: "BSRR", 0x20: "AFRL", 0x24: "AFRH", 0x28: "BRR"}
ADC_REGS = {0x0: "ISR", 0x4: "IER", 0x8: "CR", 0xC: "CFGR", 0x10: "CFGR2", 0x14: "SMPR1",
            0x18: "SMPR2", 0x4C: "JSQR"}
TIM1_BREAK_FLAGS = (1 << 7) | (1 << 8) | (1 << 13)
# the last 4 KiB of flash (Unicorn maps whole 4 KiB pages) are modelled as flash memory:
# programmed only through FLASH_KEYR/CR/SR; its two 2 KiB pages (bank 2, pages 126 and 127)
# are the firmware's settings pages A and B (firmware/board-core/src/settings.rs, store.rs)
FLASH_TOP = 0x0807_F000
SETTINGS_ADDR = 0x0807_F000
SETTINGS_PAGE_B = 0x0807_F800
FLASH_KEYS = (0x4567_0123, 0xCDEF_89AB)
FLASH_LOCK = 1 << 31
FLASH_BSY = 1 << 16
MOE = 1 << 15


def _split_uncached(addr):
    for base in sorted(PERIPHERALS, reverse=True):
        if base <= addr < base + 0x400:
            return base, addr - base
    if 0xE000_0000 <= addr < 0xE010_0000:
        return addr & ~0xFF, addr & 0xFF
    return addr & ~0x3FF, addr & 0x3FF


# the plain memory: flash below the modelled top page, SRAM, CCM SRAM, the handlers' stop
# page, system memory
MEMORY = [(0x0800_0000, FLASH_TOP - 0x0800_0000), (0x2000_0000, 0x2_0000),
          (0x1000_0000, 0x8000), (STOP, 0x1000), (0x1FFF_0000, 0x1_0000)]


def _plain_write(base, off4):
    """Whether a write to this register only stores its value (True), sets or resets GPIO
    output bits (None: BSRR, BRR), or is one of Machine._write's other special cases
    (False)."""
    if base in (0x4800_0000, 0x4800_0400, 0x4800_0800) and off4 in (0x18, 0x28):
        return None
    return not (base in (0x4000_7000, 0x5000_0000, 0x5000_0100, 0x4001_2C00)
                or (base, off4) in ((0x4002_1000, 0x8), (0x4000_1000, 0x10), (0x4002_0C00, 0x4),
                                    (0x4000_4400, 0x28), (0x4000_4400, 0x20),
                                    (0x4000_4400, 0x18), (0x4000_3000, 0x0),
                                    (0xE000_ED00, 0x94))
                or (base == 0x4002_2000 and off4 in (0x8, 0x10, 0x14, 0x18))
                or (base in (0xE000_E100, 0xE000_E200) and off4 < 0x20))


_SPLIT = {}         # address -> (base, offset)
_READ_DECODE = {}   # address -> ((base, aligned offset), special read or None, shift)
_WRITE_DECODE = {}  # address -> (base, offset, aligned offset, key, peripheral, register,
#                                  plain: True, None for a GPIO set/reset, False otherwise)


def load_elf(path):
    """(PT_LOAD segments as (paddr, bytes), entry) of a little-endian ELF32."""
    data = open(path, "rb").read()
    if data[:4] != b"\x7fELF" or data[4] != 1:
        raise ValueError(f"{path}: not an ELF32 file")
    e_phoff, = struct.unpack_from("<I", data, 28)
    e_phentsize, e_phnum = struct.unpack_from("<HH", data, 42)
    segs = []
    for i in range(e_phnum):
        p_type, p_offset, _vaddr, p_paddr, p_filesz, _memsz, _flags, _align = struct.unpack_from(
            "<8I", data, e_phoff + i * e_phentsize)
        if p_type == 1 and p_filesz:
            segs.append((p_paddr, data[p_offset:p_offset + p_filesz]))
    return segs


def elf_symbol(path, name, suffix=False):
    """The address of symbol `name` in an ELF32's .symtab (None if absent); with `suffix`,
    of the first symbol whose name ends with `name` (a v0-mangled one, for instance)."""
    with open(path, "rb") as f:
        data = f.read()
    e_shoff, = struct.unpack_from("<I", data, 32)
    e_shentsize, e_shnum = struct.unpack_from("<HH", data, 46)
    sections = [struct.unpack_from("<10I", data, e_shoff + i * e_shentsize)
                for i in range(e_shnum)]
    for sh in sections:
        if sh[1] != 2:                                   # SHT_SYMTAB
            continue
        strtab = sections[sh[6]]                         # sh_link
        for off in range(sh[4], sh[4] + sh[5], 16):
            st_name, st_value = struct.unpack_from("<II", data, off)
            start = strtab[4] + st_name
            end = data.index(b"\0", start)
            sym = data[start:end]
            if sym == name.encode() or (suffix and sym.endswith(name.encode())):
                return st_value
    return None


class RlLoad:
    """A standstill motor as three star-connected R-L branches (the paper's machine's
    stator: Rs = 10.5 ohm, L = 0.07 H), driven by the PWM duties' period averages: enough
    current for the drive to magnetize without a no-current fault."""

    def __init__(self, r=10.5, l=0.07):
        self.r, self.l = r, l
        self.i = [0.0, 0.0, 0.0]

    def period(self, duties, enabled, vdc, ts=200e-6):
        if not enabled:
            # switches off: the current decays through the diodes into the bus quickly
            self.i = [0.0, 0.0, 0.0]
            return
        m = sum(duties) / 3
        v = [(d - m) * vdc for d in duties]
        a = math.exp(-self.r * ts / self.l)
        self.i = [v[k] / self.r + (self.i[k] - v[k] / self.r) * a for k in range(3)]


class InductionMotorLoad:
    """The paper's induction machine (Table 1, J = 0.01 kg m^2, B = 2e-3 N m s/rad) as
    the power stage's load: the same equations as the project's plant
    (`crates/acim-plant/src/machine.rs`, eq. 1-3 in the stationary frame, states i_s and
    psi_r, RK4 with `substeps` per period), driven by the period averages of the PWM
    duties with the inverter's dead-time and device-drop error (the plant's averaged
    inverter: each leg's pole voltage loses s (t_dead/T Vdc + V_drop), s = clamp(i/band,
    -1, 1)). `torque` is a passive load (N m, opposing the rotation)."""

    def __init__(self, rs=10.5, rr=8.4, ls=0.56, lr=0.56, lm=0.54, p=2, j=0.01, b=2e-3,
                 dead_time=1.5e-6, drop=1.0, band=0.05, substeps=5):
        self.p, self.j, self.b = p, j, b
        self.kr = lm / lr
        self.inv_tau_r = rr / lr
        self.lm_over_tau_r = lm * self.inv_tau_r
        self.rseq = rs + self.kr * self.kr * rr
        self.inv_sigma_ls = 1.0 / (ls - lm * lm / lr)
        self.kt = 1.5 * p * self.kr
        self.dead_time, self.drop, self.band = dead_time, drop, band
        self.substeps = substeps
        self.x = [0.0] * 5          # i_alpha, i_beta, psi_alpha, psi_beta, Omega
        self.i = [0.0, 0.0, 0.0]
        self.torque = 0.0

    @property
    def speed_rpm(self):
        return self.x[4] * 30.0 / math.pi

    def _deriv(self, x, va, vb):
        ia, ib, pa, pb, w = x
        we = self.p * w
        dia = self.inv_sigma_ls * (va - self.rseq * ia
                                   + self.kr * (self.inv_tau_r * pa + we * pb))
        dib = self.inv_sigma_ls * (vb - self.rseq * ib
                                   + self.kr * (self.inv_tau_r * pb - we * pa))
        dpa = -self.inv_tau_r * pa + self.lm_over_tau_r * ia - we * pb
        dpb = -self.inv_tau_r * pb + self.lm_over_tau_r * ib + we * pa
        te = self.kt * (pa * ib - pb * ia)
        tl = self.torque * max(-1.0, min(1.0, w / 0.5))   # passive: opposes the motion
        dw = (te - self.b * w - tl) / self.j
        return [dia, dib, dpa, dpb, dw]

    def period(self, duties, enabled, vdc, ts=200e-6):
        if not enabled:
            # switches off: the currents collapse through the diodes within a period or
            # two (the plant's freewheel model); the rotor flux decays with tau_r
            self.x[0] = self.x[1] = 0.0
            h = ts
            self.x[2] *= math.exp(-self.inv_tau_r * h)
            self.x[3] *= math.exp(-self.inv_tau_r * h)
            self.x[4] += h * (-self.b * self.x[4]) / self.j
            self.i = [0.0, 0.0, 0.0]
            return
        delta = self.dead_time / ts
        h = ts / self.substeps
        for _ in range(self.substeps):
            ia, ib = self.x[0], self.x[1]
            ph = [ia, -0.5 * ia + 0.8660254 * ib, -0.5 * ia - 0.8660254 * ib]
            pole = []
            for d, i in zip(duties, ph):
                s = max(-1.0, min(1.0, i / self.band))
                pole.append(d * vdc - s * (delta * vdc + self.drop))
            va = (2 * pole[0] - pole[1] - pole[2]) / 3.0
            vb = (pole[1] - pole[2]) / math.sqrt(3.0)
            x = self.x
            k1 = self._deriv(x, va, vb)
            k2 = self._deriv([a + 0.5 * h * b for a, b in zip(x, k1)], va, vb)
            k3 = self._deriv([a + 0.5 * h * b for a, b in zip(x, k2)], va, vb)
            k4 = self._deriv([a + h * b for a, b in zip(x, k3)], va, vb)
            self.x = [a + h / 6.0 * (b + 2 * c + 2 * d + e)
                      for a, b, c, d, e in zip(x, k1, k2, k3, k4)]
        ia, ib = self.x[0], self.x[1]
        self.i = [ia, -0.5 * ia + 0.8660254 * ib, -0.5 * ia - 0.8660254 * ib]


class Machine:
    """The emulated MCU with its peripherals, running one ELF."""

    def __init__(self, elf, pwr_gated_writes=False, load=None, dc_bus=325.0,
                 settings_pages=None, current_offset_counts=0, tx_bytes_per_period=None,
                 torn=(), board="generic"):
        """`settings_pages`: the two 2 KiB settings pages' contents (A, then B: 4 KiB) at
        power-up (default erased), e.g. another Machine's `settings_pages()` after a `save`:
        a reboot with that flash.
        `current_offset_counts`: added to every phase-current sample (an amplifier whose
        bias is off). `tx_bytes_per_period`: the UART transmitter's pace (115 200 baud
        carries 2.3 bytes per 200 us period; None: it takes every byte at once).
        `torn`: offsets (from 0x0807_F000, page A's start) of settings-page double words a
        power cut left half written: reading one is an ECC double error (FLASH_ECCR.ECCD, NMI).
        `board`: the power board's measurement chain and ADC plan (a key of BOARDS)."""
        self.board = BOARDS[board]
        self.uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        self.uc.ctl_set_cpu_model(UC_CPU_ARM_CORTEX_M4)
        self._callbacks = []
        self.flash_top = bytearray(b"\xff" * 0x1000)
        if settings_pages is not None:
            if len(settings_pages) != 0x1000:
                raise ValueError("settings_pages must be 4096 bytes (pages A and B)")
            self.flash_top[:] = settings_pages
        self._flash_key = 0          # unlock sequence position
        # double words (offsets in flash_top) with an ECC double error; reading one sets
        # FLASH_ECCR and raises the NMI (RM0440 3.3.4)
        self.flash_torn = set(torn)
        self.nmi_pending = False
        self._ecc_replay = None
        self.flash_ops = 0           # erase and double-word program operations begun
        self.cut_at_op = None        # power cut during this flash operation (1-based)
        self.cut_completes = False   # ... or right after it completed (nothing torn)
        self._flash_half = None      # first word of a double word being programmed
        self.uc.mmio_map(FLASH_TOP, 0x1000, self._flash_mem_read, None,
                         self._flash_mem_write, None)
        for base, size in MEMORY:
            self.uc.mem_map(base, size)
        for paddr, blob in load_elf(elf):
            self.uc.mem_write(paddr, blob)
        for base, size in [(0x4000_0000, 0x3_0000), (0x4800_0000, 0x2000),
                           (0x5000_0000, 0x2000), (0xE000_0000, 0x10_0000)]:
            self._map_peripherals(base, size)
        # peripheral bit-band alias: one word per bit of 0x4000_0000.. (the HAL uses it)
        self.uc.mmio_map(0x4200_0000, 0x200_0000, self._bitband_read, None,
                         self._bitband_write, None)
        self.regs = {}           # (base, offset) -> value
        self.writes = []         # (instret, peripheral, register, value)
        self.write_offsets = []  # the register offset of each write, for the field decoding
        self.boot_writes = None  # number of writes before the first NVIC unmask
        self.events = []         # ordered named events for rule checks
        self.instret = 0         # instructions executed by the main program
        self.periods = 0
        self.isr_instructions = []
        self.count_isr = False
        self.trace_isr = False   # record each interrupt's executed PCs (isr_traces)
        self.isr_traces = []     # one list of executed instruction addresses per interrupt
        self.tx = bytearray()
        self.rx = bytearray()
        self.rx_history = bytearray()
        self.break_after = None  # inject a break this many ISR instructions into the handler
        self.conversion_after = None  # complete a new ADC sequence this far into the handler
        self.iwdg_feeds = 0
        self.iwdg_started = False
        self.nvic_enabled = set()
        self.nvic_pending = set()     # set by software through NVIC_ISPR
        self.measure_masked = False      # measure the main program's masked sections
        self.masked_longest = 0          # the longest run of main-program instructions
        self.masked_longest_at = None    #   with PRIMASK set, and the address it began at
        self._masked_run = 0
        self._masked_from = None
        self._masked_hook = None
        self._in_main = False
        self.slow_isr_runs = 0           # slow-task interrupts taken
        self.slow_isr_instructions = []  # their instructions, while counting
        self.break_active = False
        self.cordic_results = []
        self.load = load or RlLoad()
        self.dc_bus = dc_bus
        self.pwr_gated_writes = pwr_gated_writes
        self.moe_history = []    # (period, moe)
        self.current_offset_counts = current_offset_counts
        self.isr_stopped = False  # the control interrupt is never taken (a hung ISR)
        self.uart_ore = False     # USART2_ISR.ORE: the RX FIFO overflowed
        self.tx_pace = tx_bytes_per_period
        self._tx_credit = 8.0 if tx_bytes_per_period is not None else None
        self.selftest = False
        self.mpu_guard = None       # (base, size) of the no-access MPU region, once enabled
        self.mpu_violation = None   # first address accessed inside it
        self._mpu_pending = False
        self._reset_values()
        sp, reset = struct.unpack("<II", bytes(self.uc.mem_read(0x0800_0000, 8)))
        self.vectors = [struct.unpack_from("<I", bytes(self.uc.mem_read(0x0800_0000 + 4 * i, 4)))[0]
                        for i in range(16 + 102)]
        self.uc.reg_write(UC_ARM_REG_SP, sp)
        self.pc = reset
        self.halted = None
        self._block_counts = {}

    # --- registers ---------------------------------------------------------------------
    def _reset_values(self):
        r = self.regs
        r[(0x4002_1000, 0x0)] = 0x0000_0500     # RCC_CR: HSION, HSIRDY
        r[(0x4002_1000, 0x8)] = 0x0000_0005     # RCC_CFGR: SW = SWS = HSI16
        r[(0x4002_1000, 0xC)] = 0x0000_1000     # RCC_PLLCFGR
        r[(0x4002_1000, 0x58)] = 0x0000_0400    # RCC_APB1ENR1: RTCAPBEN
        r[(0x4000_7000, 0x0)] = 0x0000_0200     # PWR_CR1: VOS = Range 1
        r[(0x4000_7000, 0x8)] = 0x0000_8000     # PWR_CR3
        r[(0x4000_7000, 0x80)] = 0x0000_0100    # PWR_CR5: R1MODE = 1 (boost off)
        r[(0x4002_2000, 0x0)] = 0x0000_0600     # FLASH_ACR
        r[(0x4002_2000, 0x14)] = 0xC000_0000    # FLASH_CR: LOCK, OPTLOCK
        r[(0x4002_2000, 0x20)] = 0xFFEF_F8AA    # FLASH_OPTR (factory): DBANK = 1
        r[(0x4800_0000, 0x0)] = 0xABFF_FFFF     # GPIOA_MODER
        r[(0x4800_0400, 0x0)] = 0xFFFF_FEBF     # GPIOB_MODER
        r[(0x4800_0800, 0x0)] = 0xFFFF_FFFF     # GPIOC_MODER
        for adc in (0x5000_0000, 0x5000_0100):
            r[(adc, 0x8)] = 0x2000_0000         # ADC_CR: DEEPPWD
            r[(adc, 0xC)] = 0x8000_0000         # ADC_CFGR: JQDIS
        r[(0x4001_2C00, 0x2C)] = 0xFFFF         # TIM1_ARR
        r[(0xE004_2000, 0x0)] = 0x1000_6469     # DBGMCU_IDCODE
        r[(0xE000_ED00, 0x0)] = 0x410F_C241     # CPUID
        r[(0xE000_E010, 0x1C)] = 0x4000_0000    # SysTick CALIB

    @staticmethod
    def _split(addr):
        """(peripheral base, offset) of an address: a pure function of it, so each address's
        answer is computed once (the main loop polls a few registers hundreds of times a
        period)."""
        s = _SPLIT.get(addr)
        if s is None:
            s = _SPLIT[addr] = _split_uncached(addr)
        return s

    def _bitband_read(self, uc, off, size, _d):
        byte_off, bitn = off // 32, (off % 32) // 4
        addr = 0x4000_0000 + byte_off
        v = self._read(uc, addr & ~3, 4, None)
        return (v >> ((addr & 3) * 8 + bitn)) & 1

    def _bitband_write(self, uc, off, size, value, _d):
        byte_off, bitn = off // 32, (off % 32) // 4
        addr = 0x4000_0000 + byte_off
        a4 = addr & ~3
        sh = (addr & 3) * 8 + bitn
        v = self._read(uc, a4, 4, None) if not (0x4000_7000 <= a4 < 0x4000_7400) else \
            self.reg(0x4000_7000, a4 - 0x4000_7000)
        v = (v | (1 << sh)) if value & 1 else (v & ~(1 << sh))
        self._write(uc, a4, 4, v, None)

    def reg(self, base, off):
        return self.regs.get((base, off), 0)

    def _name(self, base, off):
        if base in PERIPHERALS:
            p, names = PERIPHERALS[base]
            if p.startswith("GPIO"):
                names = GPIO_REGS
            elif p in ("ADC1", "ADC2"):
                names = ADC_REGS
            return p, names.get(off, f"+0x{off:03X}")
        return None, None

    def _pwr_clocked(self):
        return bool(self.reg(0x4002_1000, 0x58) & (1 << 28))

    def _map_peripherals(self, base, size):
        """Maps `base`..`base + size` to the peripheral models (_read, _write). The main
        loop polls a few registers hundreds of times a period, so a peripheral access is
        the emulation's most frequent event: with the pinned binding (requirements.txt) the
        callbacks are registered with the library directly, one Python call each instead
        of three (the binding's exception guard, its adapter, ours); an exception in a
        model is kept and raised by emu_start, as the binding does."""
        uc = self.uc
        if _uclib is None:
            # Unicorn passes the offset into the mapped region, not the address
            uc.mmio_map(base, size, lambda _uc, off, n, _d: self._read(uc, base + off, n, None),
                        None, lambda _uc, off, n, v, _d: self._write(uc, base + off, n, v, None),
                        None)
            return
        read, write = self._read, self._write

        def on_read(_handle, off, n, _data):
            try:
                return read(uc, base + off, n, None)
            except Exception as e:
                _keep_exception(uc, e)
                return 0

        def on_write(_handle, off, n, value, _data):
            try:
                write(uc, base + off, n, value, None)
            except Exception as e:
                _keep_exception(uc, e)

        cbs = (_MMIO_READ_CFUNC(on_read), _MMIO_WRITE_CFUNC(on_write))
        self._callbacks.append(cbs)             # alive as long as the machine
        status = _uclib.uc_mmio_map(uc._uch, base, size, cbs[0], None, cbs[1], None)
        if status != 0:
            raise UcError(status)

    def _read(self, uc, addr, size, _data):
        d = _READ_DECODE.get(addr)
        if d is None:
            base, off = self._split(addr)
            d = _READ_DECODE[addr] = ((base, off & ~3), _READ_SPECIAL.get(
                base if base == 0x4000_7000 else (base, off)), (off & 3) * 8)
        key, special, shift = d
        v = self.regs.get(key, 0)
        if special is not None:
            v = special(self, v)
        return (v >> shift) & ((1 << (8 * size)) - 1)

    # registers whose reads are not their stored value (the (base, offset) of each, as
    # _split gives it; PWR by its base)
    def _read_pwr(self, v):
        return v if self._pwr_clocked() else 0          # gated bus reads as 0

    def _read_rcc_cr(self, v):
        v |= (v & (1 << 8)) << 2                        # HSIRDY follows HSION
        v |= (v & (1 << 24)) << 1                       # PLLRDY follows PLLON
        return v

    def _read_rcc_cfgr(self, v):
        return (v & ~0xC) | ((v & 0x3) << 2)            # SWS follows SW

    def _read_rcc_csr(self, v):
        return v | 0x2                                  # LSIRDY

    def _read_adc_cr(self, v):
        return v & ~(1 << 31)                           # ADCAL done at once

    def _read_usart_isr(self, v):
        txfnf = self._tx_credit is None or self._tx_credit >= 1.0
        return ((1 << 7) if txfnf else 0) | (1 << 6) | (1 << 21) | (1 << 22) \
            | ((1 << 5) if self.rx else 0) | ((1 << 3) if self.uart_ore else 0)

    def _read_usart_rdr(self, v):
        return self.rx.pop(0) if self.rx else 0

    def _read_cordic_csr(self, v):
        return v | 1 << 31                              # CORDIC RRDY

    def _read_cordic_rdata(self, v):
        return self.cordic_results.pop(0) if self.cordic_results else 0

    def _read_systick_csr(self, v):
        return v | 1 << 16                              # COUNTFLAG

    def _read_dac_sr(self, v, base):
        # DACxRDY (bits 11 and 27) follow DAC_CR.ENx (bits 0 and 16): the channel is ready
        # once enabled (RM0440 22.7.16; its wake-up time is not modelled)
        cr = self.reg(base, 0x0)
        return v | ((cr & 1) << 11) | (((cr >> 16) & 1) << 27)

    def _read_dwt_cyccnt(self, v):
        return self.instret & 0xFFFF_FFFF

    def _read_iwdg_sr(self, v):
        return 0                                        # updates done

    def _write(self, uc, addr, size, value, _data):
        d = _WRITE_DECODE.get(addr)
        if d is None:
            base, off = self._split(addr)
            off4 = off & ~3
            d = _WRITE_DECODE[addr] = (base, off, off4, (base, off4), *self._name(base, off4),
                                       _plain_write(base, off4))
        base, off, off4, key, p, name, plain = d
        if size < 4:
            old = self.regs.get(key, 0)
            shift = (off & 3) * 8
            mask = ((1 << (8 * size)) - 1) << shift
            value = (old & ~mask) | ((value << shift) & mask)
        if p is not None and self.boot_writes is None:
            # the log keeps the boot's writes (the golden file's and the register map
            # check's subject); after the boot the main loop writes a GPIO every few dozen
            # instructions, and a log of those grew by a million entries an emulated second
            self.writes.append((self.instret, p, name, value))
            self.write_offsets.append(off4)
        if plain:
            self.regs[key] = value
            return
        if plain is None:
            # GPIO BSRR (set low half, reset high half) / BRR (reset): the pins' ODR
            odr_key = (base, 0x14)
            odr = self.regs.get(odr_key, 0)
            if off4 == 0x18:
                odr = (odr | (value & 0xFFFF)) & ~(value >> 16)
            else:
                odr &= ~(value & 0xFFFF)
            self.regs[odr_key] = odr
            self.regs[key] = value
            return
        if base == 0x4000_7000:
            self.events.append(("PWR write", self._pwr_clocked()))
            if not self._pwr_clocked() or self.pwr_gated_writes:
                return                                  # dropped
        if base == 0x4002_1000 and off4 == 0x8 and (value & 3) == 3:
            self.events.append(("SW=PLL", self.reg(0x4002_2000, 0) & 0xF,
                                (self.reg(0x4000_7000, 0x80) >> 8) & 1))
        if base in (0x5000_0000, 0x5000_0100):
            self._adc_write(base, off4, value)
            return
        if base == 0x4002_2000 and off4 in (0x8, 0x10, 0x14, 0x18):
            self._flash_reg_write(off4, value)
            return
        if base == 0x4001_2C00:
            self._tim1_write(off4, value)
            return
        if base == 0x4000_1000 and off4 == 0x10:        # TIM6_SR rc_w0
            value = self.reg(base, off4) & value
        if base == 0x4002_0C00 and off4 == 0x4:         # CORDIC WDATA: sine of x pi
            x = (value - (1 << 32) if value & (1 << 31) else value) / 2**31
            q = lambda f: int(max(-2**31, min(2**31 - 1, round(f * 2**31)))) & 0xFFFF_FFFF
            self.cordic_results = [q(math.sin(math.pi * x)), q(math.cos(math.pi * x))]
        if base == 0x4000_4400 and off4 == 0x28:
            self.tx.append(value & 0xFF)
            if self._tx_credit is not None:
                self._tx_credit -= 1.0
        if base == 0x4000_4400 and off4 == 0x20 and value & (1 << 3):   # ICR.ORECF
            self.uart_ore = False
        if base == 0x4000_4400 and off4 == 0x18 and value & (1 << 3):   # RQR.RXFRQ
            self.events.append(("USART RX flush", len(self.rx)))
            self.rx.clear()                             # the RX FIFO's content discarded
        if base == 0x4000_3000 and off4 == 0x0:
            if value == 0xCCCC:
                self.iwdg_started = True
                self.events.append(("IWDG start",))
            elif value == 0xAAAA:
                self.iwdg_feeds += 1
        if base == 0xE000_ED00 and off4 == 0x94 and value & 1:   # MPU_CTRL.ENABLE
            self.events.append(("MPU enable", len(self.writes)))
            self._mpu_pending = True  # the guard's hook is added between two runs
        if base == 0xE000_E100 and off4 < 0x20:       # NVIC_ISERn
            if self.boot_writes is None:
                self.boot_writes = len(self.writes)   # the boot ends at the first unmask
            for b in range(32):
                if value & (1 << b):
                    self.nvic_enabled.add(off4 * 8 + b)
        if base == 0xE000_E200 and off4 < 0x20:       # NVIC_ISPRn: pend by software
            for b in range(32):
                if value & (1 << b):
                    self.nvic_pending.add(off4 * 8 + b)
        self.regs[(base, off4)] = value

    def _adc_write(self, base, off, value):
        if off == 0x0:                                  # ISR: rc_w1
            self.regs[(base, 0)] = self.reg(base, 0) & ~value
            return
        if off == 0x8:
            old = self.reg(base, 8)
            if value & (1 << 31) and not old & (1 << 28):
                self.events.append(("ADCAL before ADVREGEN", base))
            if value & (1 << 31):
                self.events.append(("ADCAL", base))
            if value & 1 and not old & 1:
                self.regs[(base, 0)] = self.reg(base, 0) | 1  # ADRDY
            self.regs[(base, 8)] = value & ~(1 << 31)
            return
        self.regs[(base, off)] = value

    def _tim1_write(self, off, value):
        b = 0x4001_2C00
        if off == 0x10:                                 # SR: rc_w0
            self.regs[(b, off)] = self.reg(b, off) & value
            return
        if off == 0x44 and value & MOE and not self.reg(b, off) & MOE:
            if self.break_active:
                value &= ~MOE                           # cannot set during an active break
            else:
                # CCER: whether any output is enabled (MOE with CCxE = 0 drives nothing)
                self.events.append(("MOE set", self.periods, self._calibrated(),
                                    bool(self.reg(b, 0x20) & 0x555), self._start_seen()))
        if off == 0x14 and value & 1:                   # EGR.UG
            self.regs[(b, 0x10)] = self.reg(b, 0x10) | 1
        self.regs[(b, off)] = value

    # --- flash (RM0440 3.3.6-3.3.7: unlock, page erase, double-word programming) --------
    def _flash_mem_read(self, uc, off, size, _d):
        dw = off & ~7
        if dw == self._ecc_replay:
            # the load the NMI interrupted, executed again after the handler returned
            # (Unicorn restarts an instruction stopped in a memory callback): it completes
            self._ecc_replay = None
        elif dw in self.flash_torn:
            # ECCD, BK_ECC (bank 2), ADDR_ECC: the double word's offset in bank 2
            addr = FLASH_TOP + dw - 0x0804_0000
            self.regs[(0x4002_2000, 0x18)] = (1 << 31) | (1 << 21) | addr
            self.events.append(("FLASH ECC double error", FLASH_TOP + dw))
            self.nmi_pending = True
            self._ecc_replay = dw
            uc.emu_stop()
        return int.from_bytes(self.flash_top[off:off + size], "little")

    def _flash_op(self, region):
        """Counts a flash operation; at `cut_at_op` the power fails during it: the
        double words of `region` (offset, length) are left torn and the machine stops."""
        self.flash_ops += 1
        if self.cut_at_op != self.flash_ops:
            return False
        if self.cut_completes:
            self.halted = f"power cut after flash operation {self.flash_ops}"
            self.uc.emu_stop()
            return True
        o, n = region
        for dw in range(o, o + n, 8):
            self.flash_torn.add(dw)
            # half programmed / half erased bits
            self.flash_top[dw:dw + 8] = bytes(b & 0x5A for b in self.flash_top[dw:dw + 8])
        self.halted = f"power cut during flash operation {self.flash_ops}"
        self.uc.emu_stop()
        return True

    def torn_offsets(self):
        """The settings pages' torn double words (offsets from 0x0807_F000)."""
        return sorted(self.flash_torn)

    def _flash_sr(self, bits):
        self.regs[(0x4002_2000, 0x10)] = self.reg(0x4002_2000, 0x10) | bits

    def _flash_mem_write(self, _uc, off, size, value, _d):
        cr = self.reg(0x4002_2000, 0x14)
        addr = FLASH_TOP + off
        if cr & FLASH_LOCK or not cr & 1:
            self.events.append(("FLASH write without PG", addr))
            self._flash_sr(1 << 7)                       # PGSERR
            return
        if size != 4:
            self._flash_sr(1 << 6)                       # SIZERR
            return
        if self._flash_half is None:
            if addr % 8:
                self._flash_sr(1 << 5)                   # PGAERR
                return
            self._flash_half = (addr, value)
            return
        first, lo = self._flash_half
        self._flash_half = None
        if addr != first + 4:
            self._flash_sr(1 << 5)                       # PGAERR
            return
        o = first - FLASH_TOP
        if self.flash_top[o:o + 8] != b"\xff" * 8:
            self._flash_sr(1 << 3)                       # PROGERR: not erased
            return
        self.flash_top[o:o + 8] = struct.pack("<II", lo, value)
        self.flash_torn.discard(o)
        if self._flash_op((o, 8)):
            return
        self.events.append(("FLASH program", first))

    def _flash_reg_write(self, off, value):
        b = 0x4002_2000
        if off == 0x8:                                   # KEYR
            if value == FLASH_KEYS[self._flash_key]:
                self._flash_key += 1
                if self._flash_key == 2:
                    self._flash_key = 0
                    self.regs[(b, 0x14)] = self.reg(b, 0x14) & ~FLASH_LOCK
            else:
                self._flash_key = 0
                self.events.append(("FLASH bad key", value))
            return
        if off == 0x10:                                  # SR: rc_w1
            self.regs[(b, off)] = self.reg(b, off) & ~(value & ~FLASH_BSY)
            return
        if off == 0x18:                                  # ECCR: ECCD/ECCC rc_w1
            self.regs[(b, off)] = self.reg(b, off) & ~(value & (3 << 30))
            return
        old = self.reg(b, 0x14)                           # CR
        if old & FLASH_LOCK:
            self.events.append(("FLASH CR write while locked", value))
            return
        if value & (1 << 16) and value & 2:              # STRT with PER: page erase
            dual = self.reg(b, 0x20) & (1 << 22)
            pnb = (value >> 3) & 0x7F
            if dual:
                addr = 0x0800_0000 + ((value >> 11) & 1) * 0x4_0000 + pnb * 0x800
                size = 0x800
            else:
                addr, size = 0x0800_0000 + pnb * 0x1000, 0x1000
            self.events.append(("FLASH erase", addr, size))
            if addr >= FLASH_TOP:
                o = addr - FLASH_TOP
                self.flash_top[o:o + size] = b"\xff" * size
                self.flash_torn -= set(range(o, o + size, 8))
                self._flash_op((o, size))
            else:
                self.uc.mem_write(addr, b"\xff" * size)
            value &= ~(1 << 16)                          # STRT clears when done
        self.regs[(b, 0x14)] = value

    def settings_pages(self):
        """The settings pages A and B (4 KiB at 0x0807_F000) as the flash holds them now."""
        return bytes(self.flash_top)

    def settings_page(self, page):
        """Settings page `page` ("A" or "B", 2 KiB) as the flash holds it now."""
        o = {"A": 0, "B": 0x800}[page]
        return bytes(self.flash_top[o:o + 0x800])

    def _calibrated(self):
        return any(e[0] == "ADCAL" for e in self.events)

    def _start_seen(self):
        return b"start" in bytes(self.rx_history)

    # --- hardware events ---------------------------------------------------------------
    def break_pulse(self):
        """The break input pulses: MOE cleared, BIF set (AOE = 0: stays cleared)."""
        b = 0x4001_2C00
        self.regs[(b, 0x44)] = self.reg(b, 0x44) & ~MOE
        self.regs[(b, 0x10)] = self.reg(b, 0x10) | (1 << 7)

    def moe(self):
        return bool(self.reg(0x4001_2C00, 0x44) & MOE)

    def duties(self):
        arr = self.reg(0x4001_2C00, 0x2C) or 1
        return [self.reg(0x4001_2C00, o) / arr for o in (0x34, 0x38, 0x3C)]

    def _counts(self, amps):
        b = self.board
        v = b["bias"] + b["sign"] * amps * b["shunt"] * b["gain"]
        c = int(round(v / VREF * COUNTS)) + self.current_offset_counts
        return max(0, min(COUNTS - 1, c))

    def _period_hardware(self):
        """One PWM period: the load integrates the applied duties, the ADCs convert."""
        self.periods += 1
        b = 0x4001_2C00
        running = self.reg(b, 0) & 1
        if running:
            self.regs[(b, 0x10)] = self.reg(b, 0x10) | 1   # UIF: one update per period (RCR = 1)
        if self._tx_credit is not None:
            self._tx_credit = min(8.0, self._tx_credit + self.tx_pace)
        self.load.period(self.duties(), self.moe(), self.dc_bus)
        self.moe_history.append((self.periods, self.moe()))
        if running:
            b = self.board
            ia, ib, ic = (self._counts(x) for x in self.load.i)
            bus = int(round(self.dc_bus * b["bottom"] / (b["top"] + b["bottom"]) / VREF * COUNTS))
            value = {"U": ia, "V": ib, "W": ic, "bus": min(bus, COUNTS - 1)}
            for n, adc in ((1, 0x5000_0000), (2, 0x5000_0100)):
                if self.reg(adc, 8) & (1 << 3):          # JADSTART
                    jsqr = self.reg(adc, 0x4C)           # JSQ1 bits 13:9, JSQ2 bits 19:15
                    for rank, ch in ((0, (jsqr >> 9) & 0x1F), (1, (jsqr >> 15) & 0x1F)):
                        signal = b["channels"].get((n, ch))
                        self.regs[(adc, 0x80 + 4 * rank)] = value[signal] if signal else 0
                    self.regs[(adc, 0)] = self.reg(adc, 0) | (1 << 6) | (1 << 5)
        if self.reg(0x4000_1000, 0) & 1:                 # TIM6 running (self-test)
            self.regs[(0x4000_1000, 0x10)] = self.reg(0x4000_1000, 0x10) | 1

    def _irq_pending(self):
        if self.isr_stopped:
            return None
        if ADC1_2_IRQ in self.nvic_enabled and self.reg(0x5000_0000, 4) & (1 << 6) \
                and self.reg(0x5000_0000, 0) & (1 << 6):
            return ADC1_2_IRQ
        if TIM6_IRQ in self.nvic_enabled and self.reg(0x4000_1000, 0xC) & 1 \
                and self.reg(0x4000_1000, 0x10) & 1:
            return TIM6_IRQ
        # a software-pended interrupt (lower priority than the control interrupt's: it
        # runs after it, tail-chained)
        for irq in sorted(self.nvic_pending & self.nvic_enabled):
            return irq
        return None

    # --- execution ---------------------------------------------------------------------
    def _save(self):
        """The CPU's state before an exception: Unicorn's native context (every core,
        system and floating-point register, restored at once by `_restore`)."""
        return self.uc.context_save()

    def _restore(self, ctx):
        # the exception return: the handler's registers replaced by the interrupted
        # program's (a Python write per register took a quarter of an emulated period)
        self.uc.context_restore(ctx)

    def _block_instructions(self, uc, address, size):
        # Thumb-2: a halfword whose top five bits are 0b11101/0b11110/0b11111 starts a
        # 32-bit instruction; counted once per translated block
        key = (address, size)
        n = self._block_counts.get(key)
        if n is None:
            code = bytes(uc.mem_read(address, size))
            n, i = 0, 0
            while i < len(code):
                hw = code[i] | (code[i + 1] << 8) if i + 1 < len(code) else 0
                i += 4 if (hw >> 11) in (0b11101, 0b11110, 0b11111) else 2
                n += 1
            self._block_counts[key] = n
        return n

    def _count_block(self, uc, address, size, _data):
        n = self._block_instructions(uc, address, size)
        self._isr_count += n
        if self.break_after is not None and self._isr_count >= self.break_after:
            self.break_after = None
            self.break_pulse()
        if self.conversion_after is not None and self._isr_count >= self.conversion_after:
            # the next injected sequence completes while the step still runs (a missed
            # deadline): ADC1 JEOS and JEOC set again
            self.conversion_after = None
            self.regs[(0x5000_0000, 0)] = self.reg(0x5000_0000, 0) | (1 << 6) | (1 << 5)

    def _masked_block(self, uc, address, size, _data):
        if not self._in_main:
            return
        # the main program's instructions executed with PRIMASK set, counted by basic
        # block (PRIMASK read at each block's start: a `cpsid`/`cpsie` inside a block
        # moves the count by at most that block's length)
        if uc.reg_read(UC_ARM_REG_PRIMASK) & 1:
            if self._masked_run == 0:
                self._masked_from = address
            self._masked_run += self._block_instructions(uc, address, size)
            if self._masked_run > self.masked_longest:
                self.masked_longest = self._masked_run
                self.masked_longest_at = self._masked_from
        else:
            self._masked_run = 0

    def _flush(self):
        # drop translated code (flash and CCM) so that a hook added or removed applies
        for lo, hi in ((0x0800_0000, 0x0808_0000), (0x1000_0000, 0x1000_8000)):
            self.uc.ctl_remove_cache(lo, hi)

    def _arm_mpu_guard(self):
        """The MPU as far as the firmware uses it: region 0 (RNR = 0) no access (AP = 000)
        while MPU_CTRL.ENABLE: any access inside it is a MemManage fault."""
        self._mpu_pending = False
        rbar, rasr = self.reg(0xE000_ED00, 0x9C), self.reg(0xE000_ED00, 0xA0)
        if self.reg(0xE000_ED00, 0x98) != 0 or not rasr & 1 or (rasr >> 24) & 7:
            return
        size = 1 << (((rasr >> 1) & 0x1F) + 1)
        base = rbar & ~(size - 1) & 0xFFFF_FFE0
        self.mpu_guard = (base, size)
        self.uc.hook_add(UC_HOOK_MEM_READ | UC_HOOK_MEM_WRITE, self._guard_hit,
                         begin=base, end=base + size - 1)
        self._flush()

    def _guard_hit(self, uc, _access, address, _size, _value, _data):
        if self.mpu_violation is None:
            self.mpu_violation = address
            self.events.append(("MPU guard", address))
        uc.emu_stop()

    def _stack_fault(self):
        """An access inside the guard: a stack overflow, so the MemManage exception's own
        stacking (8 words below SP) lands in the guard too: a derived fault, escalated to
        HardFault, whose stacking faults again: LOCKUP. SYSCFG_CFGR2.CLL turns LOCKUP into
        a TIM1 system break (MOE cleared, SBIF set); without that link MOE stays."""
        if self.reg(0x4001_0000, 0x1C) & 1:
            b = 0x4001_2C00
            self.regs[(b, 0x44)] = self.reg(b, 0x44) & ~MOE
            self.regs[(b, 0x10)] = self.reg(b, 0x10) | (1 << 13)
        self.halted = f"lockup: the stack reached its MPU guard at 0x{self.mpu_violation:08x}"

    def call(self, addr, r0=0, limit=200_000):
        """Runs the function at `addr` with `r0` as its first argument, as if called from
        the main program (for handlers no vector points at, e.g. the panic handler)."""
        saved = self.uc.reg_read(UC_ARM_REG_R0)
        self.vectors.append(addr)
        self.uc.reg_write(UC_ARM_REG_R0, r0)
        try:
            return self.run_exception(len(self.vectors) - 1, limit)
        finally:
            self.vectors.pop()
            self.uc.reg_write(UC_ARM_REG_R0, saved)

    def run_exception(self, vector, limit=5_000_000):
        """Runs the handler of `vector` to its return (or `limit` instructions); returns the
        instructions it executed when counting is on, else None."""
        ctx = self._save()
        sp = self.uc.reg_read(UC_ARM_REG_SP)
        self.uc.reg_write(UC_ARM_REG_SP, (sp - 104) & ~7)
        self.uc.reg_write(UC_ARM_REG_LR, STOP | 1)
        handler = self.vectors[vector]
        count = None
        h = None
        if self.count_isr or self.break_after is not None or self.conversion_after is not None:
            self._isr_count = 0
            h = self.uc.hook_add(UC_HOOK_BLOCK, self._count_block)
            self._flush()  # blocks translated before the hook would skip it
        trace, ht = None, None
        if self.trace_isr:
            trace = []
            ht = self.uc.hook_add(UC_HOOK_CODE, lambda _uc, a, _s, _d: trace.append(a))
            self._flush()
        try:
            self.uc.emu_start(handler, STOP, count=limit)
        except UcError as e:
            self.halted = f"exception in vector {vector}: {e} at 0x{self.uc.reg_read(UC_ARM_REG_PC):08x}"
        finally:
            if self.mpu_violation is not None and self.halted is None:
                self._stack_fault()
            if ht is not None:
                self.uc.hook_del(ht)
                self.isr_traces.append(trace)
                self._flush()
            if h is not None:
                self.uc.hook_del(h)
                self._flush()
                if self.count_isr:
                    count = self._isr_count
        returned = self.uc.reg_read(UC_ARM_REG_PC) == STOP
        self._restore(ctx)
        if not returned and self.halted is None:
            self.halted = f"vector {vector} did not return within {limit} instructions"
        return count

    def run(self, periods, chunk=2_000, on_period=None):
        """Runs the main program for `periods` PWM periods, delivering interrupts."""
        end = self.periods + periods
        next_period = (self.instret // INSTRUCTIONS_PER_PERIOD + 1) * INSTRUCTIONS_PER_PERIOD
        while self.periods < end and self.halted is None:
            n = min(chunk, next_period - self.instret)
            if self.measure_masked and self._masked_hook is None:
                # once: the callback counts only while the main program runs
                self._masked_hook = self.uc.hook_add(UC_HOOK_BLOCK, self._masked_block)
                self._flush()
            self._in_main = True
            try:
                self.uc.emu_start(self.pc | 1, 0xFFFF_FFFF, count=n)
            except UcError as e:
                self.halted = f"main: {e} at 0x{self.uc.reg_read(UC_ARM_REG_PC):08x}"
                break
            finally:
                self._in_main = False
            self.pc = self.uc.reg_read(UC_ARM_REG_PC)
            self.instret += n
            if self.halted is not None:
                break
            if self.nmi_pending:
                # the ECC double error's NMI, taken after the load that read the word
                self.nmi_pending = False
                self.uc.reg_write(UC_ARM_REG_PC, self.pc | 1)
                self.run_exception(NMI_VECTOR, limit=200_000)
                self.pc = self.uc.reg_read(UC_ARM_REG_PC)
                if self.halted is not None:
                    break
            if self.mpu_violation is not None:
                self._stack_fault()
                break
            if self._mpu_pending:
                self._arm_mpu_guard()
            if self.instret >= next_period:
                next_period += INSTRUCTIONS_PER_PERIOD
                self._period_hardware()
                irq = self._irq_pending()
                while irq is not None and not (self.uc.reg_read(UC_ARM_REG_PRIMASK) & 1):
                    self.nvic_pending.discard(irq)
                    self.uc.reg_write(UC_ARM_REG_PC, self.pc | 1)
                    c = self.run_exception(16 + irq)
                    self.pc = self.uc.reg_read(UC_ARM_REG_PC)
                    if irq == SLOW_TASK_IRQ:
                        self.slow_isr_runs += 1
                        if c is not None:
                            self.slow_isr_instructions.append(c)
                        if self.trace_isr:
                            # the control interrupt's traces only (the slow task runs
                            # from flash: not weighed as CCM code)
                            self.isr_traces.pop()
                    elif c is not None:
                        self.isr_instructions.append(c)
                    if self.halted is not None:
                        break
                    # a lower-priority interrupt the handler pended runs next
                    irq = self._irq_pending()
                if on_period is not None:
                    on_period(self)
        return self

    def run_until(self, cond, max_periods, **kw):
        for _ in range(max_periods):
            if cond(self):
                return True
            self.run(1, **kw)
            if self.halted:
                return False
        return cond(self)

    def send(self, text):
        self.rx.extend(text.encode())
        self.rx_history.extend(text.encode())

    def overrun(self, in_fifo, lost):
        """A receiver overrun (RM0440 USART, FIFO mode): the 8-byte RX FIFO holds
        `in_fifo`, the bytes of `lost` that arrived while it was full are gone, ORE is
        set."""
        self.rx.extend(in_fifo.encode())
        self.rx_history.extend((in_fifo + lost).encode())
        self.uart_ore = True

    def output(self):
        return self.tx.decode(errors="replace")

    def decoded_writes(self, fields, count=None):
        """The first `count` writes decoded against `fields` (an svd.FieldMaps):
        [(line, reserved bits written, read-only bits written)], the line being
        `P.REG = 0xVALUE  FIELD=v ...` (non-zero writable fields)."""
        out = []
        for (_t, p, name, v), off in list(zip(self.writes, self.write_offsets))[:count]:
            text, reserved, readonly = fields.decode(p, off, v)
            line = f"{p}.{name} = 0x{v:08X}" + (f"  {text}" if text else "")
            out.append((line, reserved, readonly))
        return out

    def write_log(self, until=None):
        """The boot's peripheral register writes as text lines (up to instruction `until`)."""
        out = []
        for t, p, name, v in self.writes:
            if until is not None and t >= until:
                break
            out.append(f"{p}.{name} = 0x{v:08X}")
        return out


_READ_SPECIAL = {
    0x4000_7000: Machine._read_pwr,
    (0x4002_1000, 0x0): Machine._read_rcc_cr,
    (0x4002_1000, 0x8): Machine._read_rcc_cfgr,
    (0x4002_1000, 0x94): Machine._read_rcc_csr,
    (0x5000_0000, 0x8): Machine._read_adc_cr,
    (0x5000_0100, 0x8): Machine._read_adc_cr,
    (0x4000_4400, 0x1C): Machine._read_usart_isr,
    (0x4000_4400, 0x24): Machine._read_usart_rdr,
    (0x4002_0C00, 0x0): Machine._read_cordic_csr,
    (0x4002_0C00, 0x8): Machine._read_cordic_rdata,
    (0xE000_E000, 0x10): Machine._read_systick_csr,
    (0xE000_1000, 0x4): Machine._read_dwt_cyccnt,
    (0x4000_3000, 0xC): Machine._read_iwdg_sr,
    (0x5000_1000, 0x34): lambda m, v: m._read_dac_sr(v, 0x5000_1000),
    (0x5000_1400, 0x34): lambda m, v: m._read_dac_sr(v, 0x5000_1400),
}


def default_elf(mode):
    import os
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target"))
    return os.path.join(target, "thumbv7em-none-eabihf", "firmware", f"acim-firmware-{mode}.elf")


if __name__ == "__main__":
    import sys
    mode = sys.argv[1] if len(sys.argv) > 1 else "power-stage"
    m = Machine(default_elf(mode))
    m.run(20)
    print(m.output())
    print("halted:", m.halted, "periods:", m.periods, "instret:", m.instret)
    print("\n".join(m.write_log()[:40]))
