//! Dead or stuck current sensors, found from the voltage the drive applies and the current
//! the machine model predicts for it.
//!
//! The software over-current trip and the current loops only see what the sensors report:
//! a channel that reads its zero code (sense cable off, amplifier dead) or sticks at one
//! value (ADC input stuck) lets the true current run away while the samples look calm.
//! This block compares, channel by channel, how far each measured phase current moved over
//! a window of `window` PWM periods with how far the stator equation says it must have
//! moved under the applied voltage, and reports [`FaultReason::CurrentSensor`] when a
//! channel that should have moved did not follow.
//!
//! # The model (design notes section 3, paper eq. 9a-9b, inverse-Gamma form)
//!
//! In the drive's frame (d along its rotor-flux estimate, rotating at the stator frequency
//! w_s), with lambda_r the referred rotor flux on the d axis:
//!
//! ```text
//! sigma Ls di_d/dt = v_d - R_sigma i_d + sigma Ls w_s i_q + (R_R / L_M) lambda_r
//! sigma Ls di_q/dt = v_q - R_sigma i_q - sigma Ls w_s i_d - w_r lambda_r
//! ```
//!
//! with `R_sigma = Rs + R_R` (Rseq of the design notes), `R_R = (Lm/Lr)^2 Rr`,
//! `L_M = Lm^2/Lr` and `w_r = p Omega` (electrical rotor speed). Each period the block
//! sums the voltage applied over it (commanded at the sample before its start: a command
//! acts over the period after the next sample) and the current at its start; at a
//! window's end
//! `model = Ts/(sigma Ls) * sum(...)`, the right-hand side summed over the window by
//! forward Euler (w_s, lambda_r and Omega taken at the window's end: they move little
//! over 1.6 ms), is the increment the model predicts over it, and the window's residual `eps = (i_end - i_start) - model` feeds a
//! slow low-pass filter, the *bias* (time constant [`BIAS_TIME`], updated once per
//! window): the steady model error (an Rs or rotor-flux error, the
//! voltage the dead time eats, the frame's half-period lag behind the applied voltage) is
//! constant in this frame, and the bias removes it from the prediction. A failing channel
//! makes the residual grow within a few periods (the current loops wind up against a
//! current that does not respond, or the current's rotation is missing from a frozen
//! channel), far faster than the bias follows.
//!
//! # The decision, once per window
//!
//! The prediction `i_pred = i_start + model + bias` (in the frame, with the bias of the
//! windows before) is turned into phase currents with the frame's angle at the window's end (inverse
//! Park, inverse Clarke), and for every channel the drive measures:
//!
//! ```text
//! change   = i_pred,x(end) - i_meas,x(start)      what the channel should have moved
//! moved    = i_meas,x(end) - i_meas,x(start)      what it moved
//! residual = i_meas,x(end) - i_pred,x(end)        what it failed to follow
//! judged when   |change| > change_threshold
//! still when    |moved| < still_threshold
//!           and |residual| > response_ratio |change| + allowance
//! astray when   |moved| >= still_threshold
//!           and |residual| > astray_ratio |change| + allowance
//! fault when a judged channel is still and no channel is astray, in this window or
//!       (twice running) in the ASTRAY_HOLD windows before, and, within ASTRAY_HOLD
//!       windows of one with a channel astray, a witness: a judged channel on the
//!       model (|residual| <= astray_ratio |change| + allowance) or every channel
//!       reading about zero (|i_meas,x| < still_threshold)
//! ```
//!
//! A failed sensor stands still (a dead channel reads its zero code, a stuck one its last
//! value) while the machine is intact, so the channels still reading the true current
//! follow the model. A machine or inverter fault moves the current away from the model
//! and does not freeze a channel: a locked rotor's current surges as its back-EMF
//! vanishes, a shorted switch's current runs up. An open motor phase does freeze its
//! channel (it reads the true 0 A), but the machine it leaves is another circuit, and
//! the other channel misses the model while moving. Both conditions keep these faults
//! for the detectors that name them (`Stall`, `OverCurrent`, `CurrentRegulation`,
//! `LossOfControl`), however far the model is off.
//!
//! The witness closes the one gap those two conditions leave: a window in which only one
//! channel is judged. After a locked rotor the model's back-EMF is the running machine's
//! until the speed estimate falls, so every channel misses the prediction; a moving
//! channel shows it (astray), but when the current loops hold the current near its
//! reference a channel can stand still in the next window while it alone is judged: at
//! 20 and 40 kHz (`fault-locked-rotor`, 500 rpm) the check named the locked rotor
//! `CurrentSensor` 3.2 ms after it, the window after the one astray, before the stall
//! detector's 27 ms.
//! A failed sensor leaves a witness: a healthy channel on the model, or (every channel
//! dead) all of them at zero; a stuck channel away from such a break needs none.
//!
//! where `allowance = RESISTANCE_UNCERTAINTY R_sigma Ts/(sigma Ls) |sum (i - i_filtered)|`
//! over the window covers a resistance error on the part of the current the bias has not
//! yet followed (after a load step).
//!
//! A dead channel stays at zero while the model asks for the current loops' wound-up
//! voltage; a stuck one stays put while, at any speed above standstill, the current's
//! rotation alone moves every phase (|i| w_s window Ts: 2 A over 1.6 ms at 4 A and 50 Hz),
//! and at standstill the current loops' correction moves it. A healthy channel follows the
//! prediction to within the model's error, which scales with the change (the transient
//! inductance's error) and is covered by `response_ratio`.
//!
//! # Bound
//!
//! A channel that fails is reported at the end of the first whole window (after the
//! failure) over which its predicted change exceeds `change_threshold`: within two
//! windows (`2 window` periods, 16 at 5 kHz) of the first such window, at any speed.
//! - All channels dead: the current loops wind up against the missing current at once,
//!   so that window is the first: reported within `2 window` periods at any speed, loaded
//!   or not (tested at 0-1500 rpm).
//! - One channel stuck at its last reading: it reads its true value until the current
//!   moves, so the first such window comes once the current's rotation (or a commanded
//!   change) moves that phase by `change_threshold` within a window. A phase near its
//!   peak barely moves, so at speed this waits for the phase to leave its peak: measured
//!   in the synthetic tests below, 4-28 periods at 500 rpm and 1500 rpm, 20-132 periods
//!   at 60 rpm (where the current moves slowly and its drift from the stuck reading is
//!   small while it is not found).
//!
//! A channel whose predicted change stays below the threshold reads its true value within
//! that threshold and cannot drive the current away: every current change the drive
//! commands is a predicted change.
//!
//! In the closed loop (`tests/sensor_faults.rs`, the seven acceptance machines at 60, 500,
//! 1500 rpm and in field weakening, two and three shunts, the nameplate's drive): dead
//! channels found after at most 16 periods, a stuck one after at most 142 at 500 rpm and
//! above and 655 at 60 rpm
//! (where the reading stays near the true current for longer); where the current loops
//! drive the true current to the trip level sooner, the hardware comparator is first.
//!
//! With a slow task the fast path only sums and keeps each window that ends, with its
//! end sample ([`SensorCheck::gather`]); the slow task judges them at its next tick
//! ([`SensorCheck::judge_pending`]): the same verdicts, each at most one slow period
//! later (a window's end costs the fast path a copy instead of the judgement's
//! inverse Park, Clarke and decision).
//!
//! # Limits
//!
//! The prediction uses the drive's estimates (the frame, its frequency, the speed and
//! the flux). When they are lost, the model no longer explains the currents, and a
//! channel that happens to stand still while the model says it moved is reported as a
//! sensor: in the robustness matrix's runaway rows (the paper machine regenerating
//! 4.5 N m at 120 rpm without the regeneration limit, the rotor at 1490 rpm against an
//! estimate of -150 rpm) the check trips `CurrentSensor` 20-40 ms before the control
//! monitor's `LossOfControl`. The trip is right, its name is not. The check runs only in
//! the closed-loop running and magnetizing steps, not during a flying start's speed
//! search (the rotor speed is not yet known) and not in open-loop V/f.
//!
//! # Use
//!
//! `no_std`, no allocation, no panic path and no division in [`SensorCheck::update`]; the
//! configuration is computed once at design time ([`SensorCheckConfig::new`], which
//! divides by validated, positive machine data). Generic over the crate's [`Num`]: the
//! f32 configuration comes from [`SensorCheckConfig::new`]; the fixed-point drive would
//! build its `Q24` configuration through its per-unit converter (its gains carry the
//! bases).

use crate::frames::{inverse_clarke, inverse_park, AlphaBeta, Dq, SinCosValue};
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::ThreePhase;
use crate::num::Units;
use crate::params::MachineParams;
use crate::supervisor::FaultReason;

/// The window, s: [`SensorCheckConfig::new`] takes the nearest whole number of periods,
/// at least [`MIN_WINDOW`] (8 periods at 5 kHz).
pub const WINDOW_TIME: f32 = 1.6e-3;
/// The fewest periods in a window.
pub const MIN_WINDOW: u32 = 4;
/// The most periods in a window.
pub const MAX_WINDOW: u32 = 64;
/// The smallest change a channel must be asked for before it is judged, as a fraction
/// of the drive's current limit I_max (0.15 I_max: 0.7 A for the paper's 4.67 A). Above
/// the residual's noise (two samples of about 0.1 % of full scale each) and the model's
/// unfiltered error within one window (a speed-estimate error of 50 rpm during a load
/// step on the paper machine: about 8 V, 0.33 A over 1.6 ms).
pub const CHANGE_FRACTION: f32 = 0.15;
/// A channel follows when its residual is at most this fraction of its predicted
/// change: room for a transient-inductance error of about +/-30 % and the forward-Euler
/// prediction's error over a window.
pub const RESPONSE_RATIO: f32 = 0.5;
/// A channel that moved is astray (the model, not a sensor, is off) when its residual is
/// above this fraction of its predicted change: stricter than [`RESPONSE_RATIO`], since a
/// model error large enough to make a still channel miss shows in the moving ones too,
/// while a failed sensor leaves the healthy channels on the model.
pub const ASTRAY_RATIO: f32 = 0.25;
/// A channel stands still when it moved less than this fraction of I_max over the window
/// (0.03 I_max: 0.14 A for the paper's 4.67 A). A failed sensor moves 0, up to its noise
/// (about 0.1 % of full scale); a healthy channel asked for a change of at least
/// [`CHANGE_FRACTION`] I_max moves, even where the model is far off (it then moves
/// elsewhere, or the other way).
pub const STILL_FRACTION: f32 = 0.03;
/// Windows after two running in which a moving channel missed the model (the machine or
/// the inverter, not a sensor, is off the model) during which no channel is judged a
/// failed sensor: a shorted switch's current runs away over a few windows, and a channel may
/// pass through a still window while it does (the other detectors trip on it).
pub const ASTRAY_HOLD: u32 = 4;
/// Time constant of the bias filter, s: long against a window (a failure's residual is
/// absorbed by 1.6 ms / 40 ms = 4 % per window), short against the thermal drift of Rs
/// and the flux's settling.
pub const BIAS_TIME: f32 = 0.04;

/// The resistance error the check allows for, as a fraction of R_sigma (0.5: the
/// stator resistance 50 % off, the paper's Fig. 8 mismatch, with the rotor's right), on
/// the part of the current the bias filter has not yet followed: after a current step
/// the filter needs [`BIAS_TIME`] to learn the new `dR i`, and until then each period
/// adds `dR (i - i_filtered) Ts/(sigma Ls)` to the residual of a healthy channel.
pub const RESISTANCE_UNCERTAINTY: f32 = 0.5;

/// Why a configuration could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorCheckError {
    /// The control period is not a positive finite number.
    ControlPeriod,
    /// The current limit is not a positive finite number.
    CurrentLimit,
    /// The machine's transient or magnetizing inductance is not positive and finite.
    Inductance,
}

/// The check's constants, from the machine data and the control period (design time).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorCheckConfig<N: Num = f32> {
    /// Ts / (sigma Ls), A/V (one period's current increment per volt).
    pub ts_over_sigma_ls: N::Gain,
    /// R_sigma = Rs + R_R, ohm.
    pub r_sigma: N::Gain,
    /// sigma Ls, H (the frame's rotation terms sigma Ls w_s i).
    pub sigma_ls: N::Gain,
    /// window R_R / L_M, 1/s (the rotor flux's d-axis back-EMF, summed over a window).
    pub rr_over_lm: N::Gain,
    /// window p: (mechanical speed x flux) -> voltage (the q-axis back-EMF
    /// p Omega lambda_r, summed over a window).
    pub back_emf: N::Gain,
    /// The window's length as a gain (`window` periods).
    pub window_gain: N::Gain,
    /// The check runs (`false`: [`SensorCheck::update`] never reports).
    pub enabled: bool,
    /// Periods per window.
    pub window: u32,
    /// The smallest predicted change per window that is judged, A.
    pub change_threshold: N,
    /// The largest residual of a following channel, as a fraction of its change.
    pub response_ratio: N::Gain,
    /// A channel that moved, whose residual is above this fraction of its change, is astray.
    pub astray_ratio: N::Gain,
    /// A channel that moved less than this over a window stands still, A.
    pub still_threshold: N,
    /// The bias filter's weight per window, window Ts / [`BIAS_TIME`] (at most 1).
    pub bias_gain: N::Gain,
    /// The resistance error allowed on a current change the bias has not yet followed,
    /// times Ts/(sigma Ls): [`RESISTANCE_UNCERTAINTY`] R_sigma Ts/(sigma Ls), A per A and
    /// period.
    pub resistance_allowance: N::Gain,
}

impl SensorCheckConfig<f32> {
    /// The constants for the machine model `machine` (the drive's, not the plant's),
    /// control period `control_period` (s) and current limit `current_limit` (A peak).
    pub fn new(
        machine: &MachineParams,
        control_period: f32,
        current_limit: f32,
    ) -> Result<Self, SensorCheckError> {
        let ts = control_period;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(SensorCheckError::ControlPeriod);
        }
        if !(current_limit.is_finite() && current_limit > 0.0) {
            return Err(SensorCheckError::CurrentLimit);
        }
        let sigma_ls = machine.transient_inductance();
        let l_m = machine.magnetizing_inductance();
        if !(sigma_ls.is_finite() && sigma_ls > 0.0 && l_m.is_finite() && l_m > 0.0) {
            return Err(SensorCheckError::Inductance);
        }
        let periods = WINDOW_TIME / ts + 0.5;
        let window = if periods >= MAX_WINDOW as f32 {
            MAX_WINDOW
        } else if periods <= MIN_WINDOW as f32 {
            MIN_WINDOW
        } else {
            periods as u32
        };
        let bias_gain = window as f32 * ts / BIAS_TIME;
        Ok(Self {
            ts_over_sigma_ls: ts / sigma_ls,
            r_sigma: machine.stator_resistance() + machine.referred_rotor_resistance(),
            sigma_ls,
            rr_over_lm: window as f32 * machine.referred_rotor_resistance() / l_m,
            back_emf: window as f32 * machine.pole_pairs_f32(),
            window_gain: window as f32,
            enabled: true,
            window,
            change_threshold: CHANGE_FRACTION * current_limit,
            response_ratio: RESPONSE_RATIO,
            astray_ratio: ASTRAY_RATIO,
            still_threshold: STILL_FRACTION * current_limit,
            bias_gain: if bias_gain < 1.0 { bias_gain } else { 1.0 },
            resistance_allowance: RESISTANCE_UNCERTAINTY
                * (machine.stator_resistance() + machine.referred_rotor_resistance())
                * ts
                / sigma_ls,
        })
    }
}

/// What the check needs each period, all at the present sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorCheckInputs<N: Num = f32> {
    /// The measured current, stationary frame, A (offsets removed): the channels are
    /// rebuilt from it at each window's ends (inverse Clarke plus the zero sequence).
    pub current_ab: AlphaBeta<N>,
    /// a + b + c as measured with three shunts (0 with two, where the third channel is
    /// derived and not judged), A.
    pub current_sum: N,
    /// Whether all three channels are measured (three shunts); otherwise a and b.
    pub three_channels: bool,
    /// The same currents in the drive's frame at this sample (Park with `angle`), A.
    pub current: Dq<N>,
    /// The voltage the last step commanded (after the modulator's limit), in the same
    /// frame, V: it acts over the period that starts at this sample (the drive's timing,
    /// as the flux observer's), so the check keeps it one update and sums it with this
    /// sample's current at the next.
    pub voltage: Dq<N>,
    /// Stator (frame) frequency w_s, rad/s electrical.
    pub stator_frequency: N,
    /// Rotor speed estimate Omega_hat, rad/s mechanical.
    pub rotor_speed: N,
    /// Rotor-flux estimate lambda_r (referred, on the d axis), Wb.
    pub rotor_flux: N,
    /// sin/cos of the frame angle at this sample.
    pub angle: SinCosValue<N>,
    /// The gates were on over the whole period that ended at this sample (false also for a
    /// period whose duties the modulator clamped to a pulse-free state on every phase).
    pub switching: bool,
}

/// The phase channels as measured: the inverse Clarke of the alpha-beta current plus the
/// zero sequence (a + b + c)/3 that the three-shunt Clarke removes (exact for both
/// sensings: with two shunts the third is the derived -a - b).
fn channels<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase>(
    inp: &SensorCheckInputs<N>,
) -> [N; 3] {
    let zero = inp.current_sum * N::ONE_THIRD;
    let [a, b, c] = inverse_clarke(inp.current_ab);
    [a + zero, b + zero, c + zero]
}

/// The running window: its length so far, where it started and the stator equation's
/// sums over it.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct Window<N: Num> {
    /// Periods in the running window.
    count: u32,
    /// The current at the window's start, in the drive's frame, A.
    start_current: Dq<N>,
    /// The phase channels at the window's start, A.
    start_phases: [N; 3],
    /// The applied voltage summed over the window, V.
    voltage_sum: Dq<N>,
    /// The current at the start of each period summed over the window, A.
    current_sum: Dq<N>,
}

/// The check's state: the previous sample, the bias and the running window.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct SensorCheck<N: Num = f32> {
    /// A previous switching sample exists (`previous` is valid).
    primed: bool,
    /// The previous switching sample's current, in the drive's frame, A.
    previous: Dq<N>,
    /// The voltage applied over the period that ends at this sample, V: the one the
    /// previous update was given (a command acts over the period after the sample that
    /// computed it; `SensorCheckInputs::voltage` is the one acting from this sample on).
    acting: Dq<N>,
    /// The running window.
    window: Window<N>,
    /// What the judgements carry from window to window.
    judgement: Judgement<N>,
    /// Windows that ended in the fast path and wait for the slow task's judgement, oldest
    /// first ([`SensorCheck::accumulate`], [`SensorCheck::judge_pending`]).
    pending: [Option<Ended<N>>; PENDING_WINDOWS],
}

/// What the judgements carry from one window to the next: the bias filter and the
/// astray history.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct Judgement<N: Num> {
    /// The model's steady error over a window (the increment it misses), filtered, A.
    bias: Dq<N>,
    /// The measured current, low-pass filtered like the bias (once per window), A.
    filtered: Dq<N>,
    /// Windows left before a standing channel may be judged a failed sensor again, after
    /// a window in which a moving channel missed the model.
    astray_hold: u32,
    /// The last window had a moving channel missing the model.
    astray_last: bool,
    /// Windows left, after one in which a moving channel missed the model, during which
    /// a standing channel is judged a failed sensor only with a channel on the model (or
    /// every channel at zero) beside it.
    astray_recent: u32,
}

/// A judgement's outcome.
enum Judged {
    /// The verdict on the window.
    Verdict(Option<FaultReason>),
    /// A non-finite value reached the state: the check starts over.
    Reset,
}

/// The most windows that can end within one slow period: a window lasts at least
/// 1.4 ms ([`WINDOW_TIME`] in whole periods, at least [`MIN_WINDOW`]) and a slow period
/// at most 2.2 ms (2 ms in whole control periods, of at most 0.4 ms where a window is
/// shorter than 1.6 ms).
pub const PENDING_WINDOWS: usize = 2;

/// What one period's sums found ([`SensorCheck::accumulate`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Period {
    /// Off or not switching: the window restarted.
    Off,
    /// The first switching sample: a window starts at it.
    Primed,
    /// Summed; the window goes on.
    Summed,
    /// Summed; the window ends at this sample.
    WindowEnd,
}

/// A window that ended, with the sample at its end, waiting to be judged.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ended<N: Num> {
    window: Window<N>,
    end: SensorCheckInputs<N>,
}

impl<N: Num + DivSqrt + ThreePhase + DivSqrt + ThreePhase> SensorCheck<N> {
    /// A check with no history.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the history (the next switching sample starts a window); keeps the bias.
    pub fn restart(&mut self) {
        self.primed = false;
        self.judgement.astray_hold = 0;
        self.judgement.astray_last = false;
        self.judgement.astray_recent = 0;
        self.window.count = 0;
        self.window.voltage_sum = Dq::default();
        self.window.current_sum = Dq::default();
        self.pending = [None; PENDING_WINDOWS];
    }

    /// The model's steady error per window (the bias filter), A, for telemetry.
    pub fn bias(&self) -> Dq<N> {
        self.judgement.bias
    }

    /// A window starts at this sample, whose channels are `phases`.
    fn start_window(&mut self, inp: &SensorCheckInputs<N>, phases: [N; 3]) {
        self.window.count = 0;
        self.window.voltage_sum = Dq::default();
        self.window.current_sum = Dq::default();
        self.window.start_current = inp.current;
        self.window.start_phases = phases;
    }

    /// One period: `Some(FaultReason::CurrentSensor)` when a measured channel did not
    /// follow the predicted current over the window that ends here, `None` otherwise
    /// (also while the gates are off, which restarts the window). The inputs are finite
    /// (the drive checks its samples and estimates before); a non-finite one is
    /// forgotten at the window's end (the state restarts) rather than judged.
    pub fn update(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        inp: &SensorCheckInputs<N>,
    ) -> Option<FaultReason> {
        match self.accumulate(cfg, inp.current, inp.voltage, inp.switching) {
            Period::Primed => {
                self.start_window(inp, channels(inp));
                None
            }
            Period::WindowEnd => {
                let window = self.window;
                self.start_window(inp, channels(inp));
                self.judge(cfg, &window, inp)
            }
            Period::Off | Period::Summed => None,
        }
    }

    /// The fast path's half of the check in a drive with a slow task: the period's sums
    /// (the sample's `current` and the `voltage` commanded for the next period, as in
    /// [`SensorCheckInputs`]; `switching` as there), and a window that ends at this
    /// sample kept, with the sample's inputs (`inputs`, called only at a window's end or
    /// start), for [`SensorCheck::judge_pending`] (the slow task's half). The judgements
    /// are [`SensorCheck::update`]'s, each made up to one slow period later.
    #[inline(always)]
    pub fn gather(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        current: Dq<N>,
        voltage: Dq<N>,
        switching: bool,
        inputs: impl FnOnce() -> SensorCheckInputs<N>,
    ) {
        match self.accumulate(cfg, current, voltage, switching) {
            Period::Primed => {
                let inp = inputs();
                self.start_window(&inp, channels(&inp));
            }
            Period::WindowEnd => {
                let inp = inputs();
                let ended = Ended {
                    window: self.window,
                    end: inp,
                };
                // two slots suffice (`PENDING_WINDOWS`); were both full, the oldest
                // would go
                match &mut self.pending {
                    [None, _] => self.pending[0] = Some(ended),
                    [Some(_), None] => self.pending[1] = Some(ended),
                    [first, second] => {
                        *first = *second;
                        *second = Some(ended);
                    }
                }
                self.start_window(&inp, channels(&inp));
            }
            Period::Off | Period::Summed => {}
        }
    }

    /// The slow task's half of the check ([`SensorCheck::gather`]): judges the windows
    /// that ended since the last call, oldest first; the first fault found.
    pub fn judge_pending(&mut self, cfg: &SensorCheckConfig<N>) -> Option<FaultReason> {
        for k in 0..PENDING_WINDOWS {
            let Some(ended) = &self.pending[k] else {
                break;
            };
            match self.judgement.judge(cfg, &ended.window, &ended.end) {
                Judged::Verdict(None) => self.pending[k] = None,
                Judged::Verdict(fault) => {
                    self.pending = [None; PENDING_WINDOWS];
                    return fault;
                }
                Judged::Reset => {
                    *self = Self::default();
                    return None;
                }
            }
        }
        None
    }

    /// The judgement of the window `w` that ended at the sample `inp`.
    fn judge(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        w: &Window<N>,
        inp: &SensorCheckInputs<N>,
    ) -> Option<FaultReason> {
        match self.judgement.judge(cfg, w, inp) {
            Judged::Verdict(fault) => fault,
            Judged::Reset => {
                *self = Self::default();
                None
            }
        }
    }

    /// One period's sums with the sample's `current` and the `voltage` commanded at it.
    /// Off or not switching, it restarts the window.
    #[inline(always)]
    fn accumulate(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        current: Dq<N>,
        voltage: Dq<N>,
        switching: bool,
    ) -> Period {
        if !cfg.enabled || !switching {
            core::hint::cold_path();
            self.restart();
            return Period::Off;
        }
        if !self.primed {
            core::hint::cold_path();
            self.primed = true;
            self.previous = current;
            self.acting = voltage;
            if self.judgement.filtered == Dq::default() {
                self.judgement.filtered = current;
            }
            return Period::Primed;
        }
        // the stator equation's terms that change within a window, summed; the frame
        // frequency, the flux and the speed are taken at the window's end (they move
        // little over 1.6 ms)
        // the period that ends here: its start's current and the voltage that acted
        // over it (the last update's input; pairing the current with this update's
        // voltage, which acts over the next period, misplaced every voltage step by a
        // period: at six-step in a bus-ripple trough, 0.4-0.7 A of a window's predicted
        // change, and a healthy channel was judged standing still)
        let i0 = self.previous;
        let v0 = self.acting;
        self.acting = voltage;
        self.window.voltage_sum.d = self.window.voltage_sum.d + v0.d;
        self.window.voltage_sum.q = self.window.voltage_sum.q + v0.q;
        self.window.current_sum.d = self.window.current_sum.d + i0.d;
        self.window.current_sum.q = self.window.current_sum.q + i0.q;
        self.previous = current;
        self.window.count = self.window.count.saturating_add(1);
        if self.window.count >= cfg.window {
            // one period of a window's (8 at 5 kHz): the summing ones fall through
            core::hint::cold_path();
            Period::WindowEnd
        } else {
            Period::Summed
        }
    }
}

/// What a window's judgement found on its channels so far ([`Judgement::judge`]).
struct Channels {
    /// A channel stands still where it should have moved.
    still: bool,
    /// A channel that moved missed the model.
    astray: bool,
    /// A channel that should have moved is on the model: the evidence that the model
    /// holds where the sensors do.
    followed: bool,
    /// Every channel reads about zero (dead sensing leaves none to follow).
    all_zero: bool,
}

impl Channels {
    /// One channel: `p` the model's prediction at the window's end, `start` the channel
    /// at its start, `meas` as measured at its end (A); `allowance` the resistance
    /// error's allowance (A).
    #[inline(always)]
    fn judge<N: Num>(&mut self, cfg: &SensorCheckConfig<N>, allowance: N, p: N, start: N, meas: N) {
        self.all_zero &= meas.abs() < cfg.still_threshold;
        let change = (p - start).abs();
        let moved = (meas - start).abs();
        let residual = (meas - p).abs();
        if change <= cfg.change_threshold {
            return;
        }
        let on_model = residual <= N::gain(cfg.astray_ratio, change) + allowance;
        self.followed |= on_model;
        if moved < cfg.still_threshold {
            self.still |= residual > N::gain(cfg.response_ratio, change) + allowance;
        } else {
            self.astray |= !on_model;
        }
    }
}

impl<N: Num + DivSqrt + ThreePhase> Judgement<N> {
    /// The judgement of the window `w` that ended at the sample `inp` (module docs, "The
    /// decision") and the bias filter's update. Inlined: into [`SensorCheck::update`]
    /// (one rate) and into [`SensorCheck::judge_pending`] (the slow task's, which the
    /// firmware runs from flash).
    #[inline(always)]
    fn judge(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        w: &Window<N>,
        inp: &SensorCheckInputs<N>,
    ) -> Judged {
        // the window's end: sigma Ls di/dt summed over it (forward Euler from each
        // period's start), the increment the model predicts, the measured one, and the
        // prediction (the model's increment corrected by the bias of the windows before)
        let (v, i) = (w.voltage_sum, w.current_sum);
        let drive_d = v.d - N::gain(cfg.r_sigma, i.d)
            + N::gain_mul(cfg.sigma_ls, inp.stator_frequency, i.q)
            + N::gain(cfg.rr_over_lm, inp.rotor_flux);
        let drive_q = v.q
            - N::gain(cfg.r_sigma, i.q)
            - N::gain_mul(cfg.sigma_ls, inp.stator_frequency, i.d)
            - N::gain_mul(cfg.back_emf, inp.rotor_speed, inp.rotor_flux);
        let model = Dq {
            d: N::gain(cfg.ts_over_sigma_ls, drive_d),
            q: N::gain(cfg.ts_over_sigma_ls, drive_q),
        };
        let end = Dq {
            d: w.start_current.d + model.d + self.bias.d,
            q: w.start_current.q + model.q + self.bias.q,
        };
        let eps = Dq {
            d: (inp.current.d - w.start_current.d) - model.d,
            q: (inp.current.q - w.start_current.q) - model.q,
        };
        if !N::all_finite([
            end.d,
            end.q,
            self.bias.d,
            self.bias.q,
            self.filtered.d,
            self.filtered.q,
        ]) {
            // a non-finite input reached the state: start over
            return Judged::Reset;
        }
        let phases = inverse_clarke(inverse_park(end, inp.angle));
        let measured = channels(inp);
        // the current the bias has not followed: |sum(i) - window i_filtered|
        let unfollowed = (i.d - N::gain(cfg.window_gain, self.filtered.d)).abs()
            + (i.q - N::gain(cfg.window_gain, self.filtered.q)).abs();
        let allowance = N::gain(cfg.resistance_allowance, unfollowed);
        // a channel that stands still where it should have moved, while every channel
        // that moved followed the model: a failed sensor (a machine fault moves some
        // channel away from the model, module docs); the judged channels are a and b,
        // and c with three shunts
        let mut c = Channels {
            still: false,
            astray: false,
            followed: false,
            all_zero: true,
        };
        // the channels one by one (an iterator over them costs about as much as their
        // judgement)
        c.judge(cfg, allowance, phases[0], w.start_phases[0], measured[0]);
        c.judge(cfg, allowance, phases[1], w.start_phases[1], measured[1]);
        if inp.three_channels {
            c.judge(cfg, allowance, phases[2], w.start_phases[2], measured[2]);
        }
        let Channels {
            still,
            astray,
            followed,
            all_zero,
        } = c;
        // a machine fault's current runs away for some windows: a channel missing while
        // moving in two windows running holds the verdict off for ASTRAY_HOLD windows (a
        // failing sensor's own jump to its stuck value misses in one window)
        if astray && self.astray_last {
            self.astray_hold = ASTRAY_HOLD;
        } else {
            self.astray_hold = self.astray_hold.saturating_sub(1);
        }
        self.astray_last = astray;
        let corroborated = followed || all_zero || self.astray_recent == 0;
        self.astray_recent = if astray {
            ASTRAY_HOLD
        } else {
            self.astray_recent.saturating_sub(1)
        };
        let fault = (still && !astray && self.astray_hold == 0 && corroborated)
            .then_some(FaultReason::CurrentSensor);
        self.bias.d = self.bias.d + N::gain(cfg.bias_gain, eps.d - self.bias.d);
        self.bias.q = self.bias.q + N::gain(cfg.bias_gain, eps.q - self.bias.q);
        self.filtered.d = self.filtered.d + N::gain(cfg.bias_gain, inp.current.d - self.filtered.d);
        self.filtered.q = self.filtered.q + N::gain(cfg.bias_gain, inp.current.q - self.filtered.q);
        Judged::Verdict(fault)
    }
}

impl SensorCheckConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`: its gains rescaled by the
    /// bases of what they multiply. `None` if a value is not representable.
    pub fn convert<N: Num + Units>(&self, b: &PerUnitBases) -> Option<SensorCheckConfig<N>> {
        let g = N::gain_from_f32;
        Some(SensorCheckConfig {
            // volt -> current increment
            ts_over_sigma_ls: g(self.ts_over_sigma_ls * b.voltage / b.current)?,
            // current -> voltage
            r_sigma: g(self.r_sigma * b.current / b.voltage)?,
            // (frequency x current) -> voltage
            sigma_ls: g(self.sigma_ls * b.frequency * b.current / b.voltage)?,
            // flux -> voltage
            rr_over_lm: g(self.rr_over_lm * b.flux / b.voltage)?,
            // (mechanical speed x flux) -> voltage
            back_emf: g(self.back_emf * b.speed * b.flux / b.voltage)?,
            window_gain: g(self.window_gain)?,
            enabled: self.enabled,
            window: self.window,
            change_threshold: N::checked_from_f32(self.change_threshold / b.current)?,
            // dimensionless
            response_ratio: g(self.response_ratio)?,
            astray_ratio: g(self.astray_ratio)?,
            still_threshold: N::from_f32(self.still_threshold / b.current),
            bias_gain: g(self.bias_gain)?,
            resistance_allowance: g(self.resistance_allowance)?,
        })
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::frames::{clarke_three, clarke_two, park, AlphaBeta};
    use std::vec::Vec;

    const TS: f32 = 200e-6;
    const P: f32 = 2.0;

    /// What goes wrong with the current channels, from `at` periods on.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Fault {
        None,
        /// Every channel reads 0 A.
        Dead,
        /// Channel `ch` holds its last reading.
        Stuck(usize),
    }

    /// A synthetic drive: the machine's stator and rotor-flux equations in the flux frame
    /// (the controller's frame is the true one), integrated in 10 sub-steps per period,
    /// under dq current PIs (2 pi 200 rad/s, with decoupling and back-EMF feedforward)
    /// whose voltage acts one period later, limited to Vdc/sqrt3 with Vdc = 325 V.
    struct Synth {
        /// The true machine (may differ from the check's model).
        plant: MachineParams,
        /// The controller's and the check's model.
        model: MachineParams,
        i: Dq,
        lambda: f32,
        theta: f32,
        w_r: f32,
        /// The command acting over the period being integrated (computed two periods
        /// before its end, as the drive's duties act over the period after the next
        /// sample) and the one computed last, acting over the next.
        v_acting: Dq,
        v_next: Dq,
        integ: Dq,
        stuck: [f32; 3],
        last_read: [f32; 3],
        /// Added to the speed the check and the controller see, rad/s electrical.
        speed_error: f32,
        /// A voltage added to the command for three periods in six, V (the per-period
        /// vector of six-step against its fundamental).
        square: f32,
        periods: u32,
    }

    impl Synth {
        fn new(rpm: f32, plant: MachineParams) -> Self {
            let model = MachineParams::paper_table1();
            let w_r = P * rpm * core::f32::consts::PI / 30.0;
            let i_d = Self::flux_current(w_r, &model);
            Self {
                plant,
                model,
                i: Dq { d: i_d, q: 0.0 },
                lambda: plant.magnetizing_inductance() * i_d,
                theta: 0.0,
                w_r,
                v_acting: Dq::default(),
                v_next: Dq::default(),
                square: 0.0,
                periods: 0,
                integ: Dq::default(),
                stuck: [0.0; 3],
                last_read: [0.0; 3],
                speed_error: 0.0,
            }
        }

        /// The flux current, weakened so that the back-EMF stays under 150 V.
        fn flux_current(w_r: f32, m: &MachineParams) -> f32 {
            let full: f32 = 1.5;
            let limit = 150.0 / (w_r.abs() * m.magnetizing_inductance()).max(1e-3);
            full.min(limit)
        }

        fn slip(&self, m: &MachineParams, i_q: f32, lambda: f32) -> f32 {
            m.referred_rotor_resistance() * i_q / lambda.max(0.05)
        }

        /// One period: integrate the plant under the voltage acting over it (commanded
        /// two periods before its end), read the channels (with `fault`), run the
        /// controller for the period after the next and return the check's inputs (with
        /// the drive's voltage: the last command, which acts from this sample on).
        fn period(&mut self, i_q_ref: f32, fault: Fault, three: bool) -> SensorCheckInputs {
            let v = self.v_acting;
            let applied = self.v_next;
            let pl = self.plant;
            let (sls, rsig, rr, lm) = (
                pl.transient_inductance(),
                pl.stator_resistance() + pl.referred_rotor_resistance(),
                pl.referred_rotor_resistance(),
                pl.magnetizing_inductance(),
            );
            let h = TS / 10.0;
            let mut w_s = 0.0;
            for _ in 0..10 {
                w_s = self.w_r + self.slip(&pl, self.i.q, self.lambda);
                let did =
                    (v.d - rsig * self.i.d + sls * w_s * self.i.q + rr / lm * self.lambda) / sls;
                let diq =
                    (v.q - rsig * self.i.q - sls * w_s * self.i.d - self.w_r * self.lambda) / sls;
                let dl = rr * self.i.d - rr / lm * self.lambda;
                self.i.d += h * did;
                self.i.q += h * diq;
                self.lambda += h * dl;
                self.theta += h * w_s;
            }
            let sc = SinCosValue {
                sin: libm_free::sin(self.theta),
                cos: libm_free::cos(self.theta),
            };
            let truth = inverse_clarke(inverse_park(self.i, sc));
            let mut read = truth;
            match fault {
                Fault::None => {}
                Fault::Dead => read = [0.0; 3],
                Fault::Stuck(ch) => {
                    if self.stuck == [0.0; 3] {
                        self.stuck = self.last_read;
                    }
                    read[ch] = self.stuck[ch];
                }
            }
            if !three {
                read[2] = -read[0] - read[1];
            }
            self.last_read = read;
            let ab: AlphaBeta = if three {
                clarke_three(read[0], read[1], read[2])
            } else {
                clarke_two(read[0], read[1])
            };
            let meas = park(ab, sc);
            // the controller, on the measurements and the model (with a speed error)
            let m = self.model;
            let w_hat = self.w_r + self.speed_error;
            let lambda_hat = self.lambda;
            let w_s_hat = w_hat + self.slip(&m, meas.q, lambda_hat);
            let wc = 2.0 * core::f32::consts::PI * 200.0;
            let (kp, ki) = (
                wc * m.transient_inductance(),
                wc * (m.stator_resistance() + m.referred_rotor_resistance()),
            );
            let i_d_ref = Self::flux_current(self.w_r, &m);
            let e = Dq {
                d: i_d_ref - meas.d,
                q: i_q_ref - meas.q,
            };
            self.integ.d += ki * TS * e.d;
            self.integ.q += ki * TS * e.q;
            let ff = Dq {
                d: -m.transient_inductance() * w_s_hat * meas.q
                    - m.referred_rotor_resistance() / m.magnetizing_inductance() * lambda_hat,
                q: m.transient_inductance() * w_s_hat * meas.d + w_hat * lambda_hat,
            };
            let mut vn = Dq {
                d: kp * e.d + self.integ.d + ff.d,
                q: kp * e.q + self.integ.q + ff.q,
            };
            let vmax = 325.0 / 1.732;
            let mag = (vn.d * vn.d + vn.q * vn.q).sqrt();
            if mag > vmax {
                vn.d *= vmax / mag;
                vn.q *= vmax / mag;
                // anti-windup: hold the integrators
                self.integ.d -= ki * TS * e.d;
                self.integ.q -= ki * TS * e.q;
            }
            self.periods += 1;
            if (self.periods / 3) % 2 == 1 {
                vn.d += self.square;
                vn.q -= self.square;
            }
            self.v_acting = self.v_next;
            self.v_next = vn;
            let _ = w_s;
            SensorCheckInputs {
                current_ab: ab,
                current_sum: if three {
                    read[0] + read[1] + read[2]
                } else {
                    0.0
                },
                three_channels: three,
                current: meas,
                voltage: applied,
                stator_frequency: w_s_hat,
                rotor_speed: w_hat / P,
                rotor_flux: lambda_hat,
                angle: sc,
                switching: true,
            }
        }

        fn peak(&self) -> f32 {
            (self.i.d * self.i.d + self.i.q * self.i.q).sqrt()
        }
    }

    /// sin and cos by range reduction and Taylor series (tests only; the crate has no
    /// libm).
    mod libm_free {
        pub fn sin(x: f32) -> f32 {
            cos(x - core::f32::consts::FRAC_PI_2)
        }
        pub fn cos(x: f32) -> f32 {
            let x = crate::math::wrap_angle(x);
            let x2 = x * x;
            let mut term = 1.0f32;
            let mut sum = 1.0f32;
            for k in 1..10 {
                term *= -x2 / ((2 * k - 1) * (2 * k)) as f32;
                sum += term;
            }
            sum
        }
    }

    fn cfg() -> SensorCheckConfig {
        SensorCheckConfig::new(&MachineParams::paper_table1(), TS, 4.67).unwrap()
    }

    /// With a slow task the fast path gathers and the slow task judges: the same verdicts
    /// as [`SensorCheck::update`]'s, each at the slow tick after the window's end (a
    /// slow period of 7 control periods against windows of 8: sometimes none, sometimes
    /// one window judged per tick; of 12 periods: up to two).
    #[test]
    fn gathered_windows_are_judged_as_at_once_one_slow_period_later() {
        let cfg = cfg();
        for divider in [5usize, 7, 12] {
            for fault in [Fault::Dead, Fault::Stuck(1)] {
                let mut s = Synth::new(500.0, MachineParams::paper_table1());
                let (mut at_once, mut split) = (SensorCheck::new(), SensorCheck::new());
                let (mut found_at_once, mut found_split) = (None, None);
                for k in 0..600 {
                    let f = if k >= 200 { fault } else { Fault::None };
                    let inp = s.period(2.0, f, false);
                    if found_at_once.is_none() && at_once.update(&cfg, &inp).is_some() {
                        found_at_once = Some(k);
                    }
                    split.gather(&cfg, inp.current, inp.voltage, true, || inp);
                    if found_split.is_none() && k % divider == 0 {
                        if split.judge_pending(&cfg).is_some() {
                            found_split = Some(k);
                        } else if found_at_once.is_none() {
                            // at a tick both have judged every window that ended
                            assert_eq!(
                                split.judgement.bias, at_once.judgement.bias,
                                "{divider} {fault:?} {k}"
                            );
                        }
                    }
                }
                let (a, b) = (found_at_once.unwrap(), found_split.unwrap());
                assert!(
                    a >= 200 && b >= a && b < a + divider,
                    "{divider} {fault:?}: {a} {b}"
                );
            }
        }
    }

    /// Runs `settle` healthy periods, then `n` periods with `fault` from the first;
    /// `i_q` gives the q-current reference per period. Returns the period (counted from
    /// the failure) the check reported in, and the largest true current magnitude.
    fn run(
        s: &mut Synth,
        fault: Fault,
        three: bool,
        settle: usize,
        n: usize,
        i_q: &dyn Fn(usize) -> f32,
    ) -> (Option<usize>, f32) {
        let cfg = cfg();
        let mut check = SensorCheck::new();
        for k in 0..settle {
            let inp = s.period(i_q(k), Fault::None, three);
            assert_eq!(check.update(&cfg, &inp), None, "healthy, period {k}");
        }
        let mut peak = 0.0f32;
        for k in 0..n {
            let inp = s.period(i_q(settle + k), fault, three);
            peak = peak.max(s.peak());
            if let Some(r) = check.update(&cfg, &inp) {
                assert_eq!(r, FaultReason::CurrentSensor);
                return (Some(k), peak);
            }
        }
        (None, peak)
    }

    const SPEEDS: [f32; 4] = [0.0, 60.0, 500.0, 1500.0];

    #[test]
    fn the_configuration_follows_the_design() {
        let c = cfg();
        assert_eq!(c.window, 8);
        assert!((c.change_threshold - 0.7005).abs() < 1e-3);
        assert!(
            (c.ts_over_sigma_ls - TS / MachineParams::paper_table1().transient_inductance()).abs()
                < 1e-9
        );
        let m = MachineParams::paper_table1();
        assert_eq!(
            SensorCheckConfig::new(&m, 0.0, 4.67),
            Err(SensorCheckError::ControlPeriod)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, f32::NAN, 4.67),
            Err(SensorCheckError::ControlPeriod)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, TS, -1.0),
            Err(SensorCheckError::CurrentLimit)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, 1e-6, 4.67).unwrap().window,
            MAX_WINDOW
        );
        assert_eq!(
            SensorCheckConfig::new(&m, 1e-3, 4.67).unwrap().window,
            MIN_WINDOW
        );
    }

    /// Healthy channels at standstill, 60, 500 and 1500 rpm (flux weakened there), with
    /// no load, a load-current step to the limit and back, and a current reversal: no
    /// report over 0.4 s, two and three shunts.
    #[test]
    fn healthy_channels_through_load_steps_are_never_reported() {
        let steps = |k: usize| match k / 500 {
            0 => 0.0,
            1 => 4.0,
            2 => -4.0,
            _ => 1.0,
        };
        for rpm in SPEEDS {
            for three in [false, true] {
                let mut s = Synth::new(rpm, MachineParams::paper_table1());
                let (hit, _) = run(&mut s, Fault::None, three, 200, 2000, &steps);
                assert_eq!(hit, None, "{rpm} rpm, three {three}");
            }
        }
    }

    /// A voltage that jumps from period to period (six-step's per-period vectors against
    /// their fundamental; here 80 V on both axes for three periods in six, on top of the
    /// current loops' command) is no sensor fault: the check pairs each period's current
    /// with the voltage that acted over it. Pairing it with the next period's voltage (the
    /// drive's last command, which acts from the sample on) put every jump a period off
    /// and reported a healthy channel at rest after 64 periods.
    #[test]
    fn voltage_jumps_between_periods_are_not_sensor_faults() {
        for rpm in SPEEDS {
            for three in [false, true] {
                let mut s = Synth::new(rpm, MachineParams::paper_table1());
                s.square = 80.0;
                let (hit, _) = run(&mut s, Fault::None, three, 200, 4000, &|_| 1.0);
                assert_eq!(hit, None, "{rpm} rpm, three {three}");
            }
        }
    }

    /// Healthy channels with the model wrong: plant Rs +50 %, R_R +30 %, sigma Ls -20 %
    /// and +20 %, a 30 rpm speed-estimate error; load steps as above: no report.
    #[test]
    fn model_errors_are_not_sensor_faults() {
        let base = MachineParams::paper_table1().data();
        let mut cases = Vec::new();
        for (rs, rr, l) in [
            (1.5, 1.0, 1.0),
            (1.0, 1.3, 1.0),
            (1.0, 1.0, 0.8),
            (1.0, 1.0, 1.2),
            (1.5, 1.3, 0.8),
        ] {
            let mut d = base;
            d.stator_resistance *= rs;
            d.rotor_resistance *= rr;
            // leakage scaled: Ls and Lr move together around Lm
            let leak_s = d.stator_inductance - d.mutual_inductance;
            let leak_r = d.rotor_inductance - d.mutual_inductance;
            d.stator_inductance = d.mutual_inductance + l * leak_s;
            d.rotor_inductance = d.mutual_inductance + l * leak_r;
            cases.push(MachineParams::new(d).unwrap());
        }
        let steps = |k: usize| if (k / 400) % 2 == 1 { 4.0 } else { 1.0 };
        for plant in cases {
            for rpm in SPEEDS {
                for err_rpm in [0.0, 30.0] {
                    let mut s = Synth::new(rpm, plant);
                    s.speed_error = P * err_rpm * core::f32::consts::PI / 30.0;
                    let (hit, _) = run(&mut s, Fault::None, false, 200, 2000, &steps);
                    assert_eq!(hit, None, "{rpm} rpm, speed error {err_rpm} rpm, {plant:?}");
                }
            }
        }
    }

    /// Every channel at 0 A, loaded (2 A of torque current) or not, at every speed: reported
    /// within two windows.
    #[test]
    fn dead_channels_are_reported_within_two_windows() {
        let bound = 2 * cfg().window as usize;
        for rpm in SPEEDS {
            for i_q in [0.0, 2.0] {
                for three in [false, true] {
                    let mut s = Synth::new(rpm, MachineParams::paper_table1());
                    let (hit, peak) = run(&mut s, Fault::Dead, three, 300, 200, &|_| i_q);
                    let k = hit.unwrap_or_else(|| panic!("{rpm} rpm, i_q {i_q}: not found"));
                    std::println!("dead, {rpm} rpm, i_q {i_q}, three {three}: {k} periods");
                    assert!(
                        k < bound,
                        "{rpm} rpm, i_q {i_q}: after {k} periods (peak {peak} A)"
                    );
                }
            }
        }
    }

    /// One channel stuck at its last reading, loaded, at every speed but standstill
    /// (two shunts: a or b; three shunts: any): reported within 200 periods (40 ms),
    /// before the true current leaves the current limit (the periods it took are printed
    /// with `--nocapture`; the module documentation quotes them).
    #[test]
    fn stuck_channels_are_reported() {
        for rpm in [60.0, 500.0, 1500.0] {
            for (three, ch) in [(false, 0), (false, 1), (true, 0), (true, 1), (true, 2)] {
                let mut s = Synth::new(rpm, MachineParams::paper_table1());
                let (hit, peak) = run(&mut s, Fault::Stuck(ch), three, 300, 2000, &|_| 2.0);
                let k =
                    hit.unwrap_or_else(|| panic!("{rpm} rpm, ch {ch}, three {three}: not found"));
                std::println!("{rpm} rpm ch {ch} three {three}: {k} periods, peak {peak}");
                assert!(k < 200, "{rpm} rpm, ch {ch}: after {k} periods");
                assert!(
                    peak < 4.67,
                    "{rpm} rpm, ch {ch}: true current {peak} A before the report"
                );
            }
        }
    }

    /// Gates off (and back on): no judgement across the gap.
    #[test]
    fn gates_off_restart_the_window() {
        let cfg = cfg();
        let mut s = Synth::new(500.0, MachineParams::paper_table1());
        let mut check = SensorCheck::new();
        for k in 0..100 {
            let mut inp = s.period(1.0, Fault::None, false);
            if k % 7 == 3 {
                inp.switching = false;
            }
            assert_eq!(check.update(&cfg, &inp), None);
        }
        let mut inp = s.period(1.0, Fault::None, false);
        inp.voltage.d = f32::NAN;
        assert_eq!(check.update(&cfg, &inp), None);
    }
}
