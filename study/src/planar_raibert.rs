//! `hopper-sim planar run --controller raibert`: the Appendix A runner
//! with its hip actuated, run by the control crate's Raibert controller
//! ([`hopper_control::planar::raibert`]) along a speed profile, with
//! pushes; per stride (apex to apex) its mean speed, the toe's apex and
//! the largest pitch, and the figures the controller is judged by.

use hopper_control::planar::raibert::RaibertConfig;
use hopper_plant::planar::PlanarEvent;
use hopper_plant::planar_general::GeneralParams;
use hopper_sil::planar::PlanarLoop;
pub use hopper_sil::planar::DT_S;
use serde::Serialize;

/// How close a stride's speed must come to its command: a tenth of it,
/// or this much for a command near standstill, m/s.
pub const SPEED_FLOOR_MPS: f64 = 0.05;
/// Strides within which a speed step must settle, and a push recover.
pub const SETTLE_HOPS: usize = 10;
/// The pitch bound, degrees.
pub const PITCH_BOUND_DEG: f64 = 5.0;
/// The apex band around the target, fraction.
pub const APEX_BAND: f64 = 0.10;
/// Strides from the start before the apex is held to its band.
pub const APEX_FROM_HOP: usize = 5;
/// A push lasts this long (its force is the impulse over it), s.
pub const PUSH_S: f64 = 0.05;

/// The machine the runs are on: [`GeneralParams::actuated_table_2_2`].
pub fn actuated_machine() -> GeneralParams {
    GeneralParams::actuated_table_2_2()
}

/// A speed command that steps at given times: `T:V,T:V,...` (s, m/s),
/// the first at 0.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SpeedProfile {
    /// `(from, speed)`, increasing in time, the first from 0 s.
    pub steps: Vec<(f64, f64)>,
}

impl SpeedProfile {
    /// Parses `T:V,...`; one clear error naming the bad item.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut steps = Vec::new();
        for item in text.split(',') {
            let (t, v) = item
                .split_once(':')
                .ok_or_else(|| format!("speed profile item `{item}` is not TIME:SPEED"))?;
            let t: f64 = t
                .trim()
                .parse()
                .map_err(|_| format!("speed profile item `{item}`: `{t}` is not a time in s"))?;
            let v: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("speed profile item `{item}`: `{v}` is not a speed in m/s"))?;
            if !(t.is_finite() && v.is_finite() && v.abs() <= 3.0) {
                return Err(format!(
                    "speed profile item `{item}`: the speed must be within +-3 m/s"
                ));
            }
            if steps.last().is_some_and(|&(t0, _)| t <= t0) {
                return Err(format!("speed profile item `{item}`: times must increase"));
            }
            steps.push((t, v));
        }
        match steps.first() {
            Some(&(0.0, _)) => Ok(SpeedProfile { steps }),
            _ => Err("the speed profile must start at time 0 (`0:SPEED,...`)".into()),
        }
    }

    /// The command at `t_s`, m/s.
    pub fn at(&self, t_s: f64) -> f64 {
        self.steps
            .iter()
            .rev()
            .find(|(t, _)| *t <= t_s)
            .map_or(0.0, |&(_, v)| v)
    }
}

/// A push on the body: an impulse at a time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Push {
    /// When it starts, s.
    pub at_s: f64,
    /// Its impulse, forward positive, N s (held for [`PUSH_S`]).
    pub impulse_ns: f64,
}

impl Push {
    /// Parses `push@T:N` (`N` in N s).
    pub fn parse(text: &str) -> Result<Self, String> {
        let rest = text
            .strip_prefix("push@")
            .ok_or_else(|| format!("`{text}`: the planar runner injects only push@TIME:IMPULSE"))?;
        let (t, n) = rest
            .split_once(':')
            .ok_or_else(|| format!("`{text}` is not push@TIME:IMPULSE (s, N s)"))?;
        let at_s: f64 = t
            .parse()
            .map_err(|_| format!("`{text}`: `{t}` is not a time in s"))?;
        let impulse_ns: f64 = n
            .parse()
            .map_err(|_| format!("`{text}`: `{n}` is not an impulse in N s"))?;
        if !(at_s.is_finite() && at_s >= 0.0 && impulse_ns.is_finite() && impulse_ns.abs() <= 200.0)
        {
            return Err(format!(
                "`{text}`: the time must be at least 0 and the impulse within +-200 N s"
            ));
        }
        Ok(Push { at_s, impulse_ns })
    }
}

/// One stride, apex to apex.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Stride {
    /// Its ending apex's time, s.
    pub t_s: f64,
    /// The toe's height at that apex, m.
    pub apex_m: f64,
    /// The hip's mean forward speed over the stride, m/s.
    pub speed_mps: f64,
    /// The command at its end, m/s.
    pub command_mps: f64,
    /// The largest |pitch| over it, degrees.
    pub max_pitch_deg: f64,
    /// Where the foot was placed ahead of the hip at its touchdown, m.
    pub foot_ahead_m: f64,
}

/// How one speed step (or a push) settled.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Settling {
    /// When it came, s.
    pub at_s: f64,
    /// The command after it, m/s.
    pub command_mps: f64,
    /// Strides after it until every stride to the next step is within
    /// the band (`None`: never).
    pub hops: Option<usize>,
    /// The steady speed: the mean of the strides in the band, m/s.
    pub steady_mps: Option<f64>,
    /// The largest |pitch| over the strides after it, to the next change,
    /// degrees.
    pub max_pitch_deg: f64,
}

/// A run and its figures.
#[derive(Clone, Debug, Serialize)]
pub struct RaibertRun {
    /// The strides.
    pub strides: Vec<Stride>,
    /// Each speed step's settling, in time order.
    pub steps: Vec<Settling>,
    /// Each push's recovery.
    pub pushes: Vec<Settling>,
    /// The largest |pitch| over the run but the strides after a push,
    /// degrees (a push on the body above the machine's centre of mass
    /// turns it: [`Settling::max_pitch_deg`] says by how much).
    pub max_pitch_deg: f64,
    /// The apex target, m.
    pub target_apex_m: f64,
    /// The largest apex error from [`APEX_FROM_HOP`] on, the strides after
    /// a push left out, fraction of the target.
    pub apex_max_error: f64,
    /// When it fell (hip below half the leg or |pitch| beyond 45 deg), s.
    pub fell_at_s: Option<f64>,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Hip position, height, pitch and leg angle every 10 ms, for the
    /// drawing: `[t, x, z, phi, theta, leg length]`.
    #[serde(skip)]
    pub frames: Vec<[f64; 6]>,
}

impl RaibertRun {
    /// Whether every figure is within its bound.
    pub fn passes(&self) -> bool {
        self.fell_at_s.is_none()
            && self.max_pitch_deg <= PITCH_BOUND_DEG
            && self.apex_max_error <= APEX_BAND
            && self
                .steps
                .iter()
                .chain(&self.pushes)
                .all(|s| s.hops.is_some_and(|h| h <= SETTLE_HOPS))
    }
}

/// Whether `speed` is within the band of `command`.
fn in_band(speed: f64, command: f64) -> bool {
    (speed - command).abs() <= (0.1 * command.abs()).max(SPEED_FLOOR_MPS)
}

/// How the strides after `at_s` (to `until_s`) settled on `command`.
fn settling(strides: &[Stride], at_s: f64, until_s: f64, command: f64) -> Settling {
    let after: Vec<&Stride> = strides
        .iter()
        .filter(|s| s.t_s > at_s && s.t_s <= until_s)
        .collect();
    // The first stride from which every later one is in the band (the
    // stride that spans the change itself does not count).
    let from = (0..after.len()).find(|&i| after[i..].iter().all(|s| in_band(s.speed_mps, command)));
    let steady = from
        .filter(|&i| i < after.len())
        .map(|i| after[i..].iter().map(|s| s.speed_mps).sum::<f64>() / (after.len() - i) as f64);
    Settling {
        at_s,
        command_mps: command,
        hops: from.filter(|&i| i < after.len()).map(|i| i + 1),
        steady_mps: steady,
        max_pitch_deg: after.iter().map(|s| s.max_pitch_deg).fold(0.0, f64::max),
    }
}

/// Runs the actuated machine for `duration_s` along `profile` with
/// `pushes`, from an apex 0.8 m up at the profile's first speed.
pub fn simulate(
    profile: &SpeedProfile,
    pushes: &[Push],
    duration_s: f64,
    cfg: RaibertConfig,
) -> Result<RaibertRun, String> {
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 600.0) {
        return Err(format!("--duration {duration_s} must be in (0, 600] s"));
    }
    let p = actuated_machine();
    let mut lp = PlanarLoop::new(p, cfg, profile.at(0.0)).map_err(|e| format!("{e:?}"))?;
    let mut strides = Vec::new();
    let mut frames = Vec::new();
    let mut last_apex: Option<(f64, f64)> = None;
    let mut stride_pitch: f64 = 0.0;
    let mut first_pitch: f64 = 0.0;
    let mut fell_at_s = None;
    let mut foot_ahead = 0.0;
    let steps = (duration_s / DT_S).round() as usize;
    for k in 0..steps {
        let t = k as f64 * DT_S;
        let st = lp.state();
        let est = lp.estimate();
        let cmd = lp.control(&est, profile.at(t));
        let push_n = pushes
            .iter()
            .filter(|p| t >= p.at_s && t < p.at_s + PUSH_S)
            .map(|p| p.impulse_ns / PUSH_S)
            .sum();
        let pitch = st.phi_rad.abs().to_degrees();
        stride_pitch = stride_pitch.max(pitch);
        if k % 100 == 0 {
            frames.push([t, st.x_m, st.z_m, st.phi_rad, st.theta_rad, st.leg_length_m]);
        }
        if st.z_m < 0.5 * p.leg_length_m || pitch > 45.0 || !st.z_m.is_finite() {
            fell_at_s = Some(t);
            break;
        }
        let mut apex = None;
        let mut touchdown = false;
        lp.advance(cmd, push_n, &mut |e| match e {
            PlanarEvent::Apex { t_s, apex: a } => apex = Some((t_s, a)),
            PlanarEvent::Touchdown { .. } => touchdown = true,
            PlanarEvent::Liftoff { .. } => {}
        });
        if touchdown {
            let s = lp.state();
            foot_ahead = s.leg_length_m * s.theta_rad.sin();
        }
        if let Some((t_s, a)) = apex {
            let x = lp.state().x_m;
            if let Some((t0, x0)) = last_apex {
                strides.push(Stride {
                    t_s,
                    apex_m: a.z_m - p.leg_length_m,
                    speed_mps: (x - x0) / (t_s - t0),
                    command_mps: profile.at(t_s),
                    max_pitch_deg: stride_pitch,
                    foot_ahead_m: foot_ahead,
                });
            }
            if last_apex.is_none() {
                first_pitch = stride_pitch;
            }
            last_apex = Some((t_s, x));
            stride_pitch = 0.0;
        }
    }
    let end = fell_at_s.unwrap_or(duration_s);
    let bounds: Vec<f64> = profile
        .steps
        .iter()
        .map(|&(t, _)| t)
        .chain(pushes.iter().map(|p| p.at_s))
        .chain([end])
        .collect();
    let next_after = |t: f64| {
        bounds
            .iter()
            .copied()
            .filter(|&b| b > t)
            .fold(end, f64::min)
    };
    let steps_settled = profile
        .steps
        .iter()
        .filter(|(t, _)| *t < end)
        .map(|&(t, v)| settling(&strides, t, next_after(t), v))
        .collect();
    let pushes_settled = pushes
        .iter()
        .filter(|p| p.at_s < end)
        .map(|p| settling(&strides, p.at_s, next_after(p.at_s), profile.at(p.at_s)))
        .collect();
    // The pitch before the first apex, then each stride's but those from a
    // push to the next change.
    let pushed = |t: f64| pushes.iter().any(|p| t > p.at_s && t <= next_after(p.at_s));
    let undisturbed_pitch = strides
        .iter()
        .filter(|s| !pushed(s.t_s))
        .map(|s| s.max_pitch_deg)
        .fold(first_pitch, f64::max);
    let target = f64::from(cfg.target_apex_m);
    let apex_max_error = strides
        .iter()
        .skip(APEX_FROM_HOP)
        .filter(|s| !pushed(s.t_s))
        .map(|s| (s.apex_m - target).abs() / target)
        .fold(0.0, f64::max);
    Ok(RaibertRun {
        strides,
        steps: steps_settled,
        pushes: pushes_settled,
        max_pitch_deg: undisturbed_pitch,
        target_apex_m: target,
        apex_max_error,
        fell_at_s,
        duration_s: end,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_and_pushes_parse_or_say_why() {
        let p = SpeedProfile::parse("0:0,3:0.5,8:1.0,13:0").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(p.at(2.9), 0.0);
        assert_eq!(p.at(3.0), 0.5);
        assert_eq!(p.at(12.0), 1.0);
        assert_eq!(p.at(60.0), 0.0);
        assert!(SpeedProfile::parse("1:0").is_err_and(|e| e.contains("time 0")));
        assert!(SpeedProfile::parse("0:0,3:x").is_err_and(|e| e.contains("`x`")));
        assert!(SpeedProfile::parse("0:0,3:1,2:0").is_err_and(|e| e.contains("increase")));
        assert_eq!(
            Push::parse("push@20:20"),
            Ok(Push {
                at_s: 20.0,
                impulse_ns: 20.0
            })
        );
        assert!(Push::parse("estop@2").is_err());
    }

    /// The forward-running figures, on the plant: the speed profile 0,
    /// 0.5, 1.0, 0 m/s settles within 10 hops of each step to within 10%
    /// (or 0.05 m/s at standstill), the pitch stays within 5 degrees and
    /// the apex within 10% of its target, 60 s without a fall.
    #[test]
    fn raibert_tracks_the_speed_profile() {
        let profile = SpeedProfile::parse("0:0,3:0.5,8:1.0,13:0").unwrap_or_else(|e| panic!("{e}"));
        let r = simulate(&profile, &[], 60.0, RaibertConfig::table_2_2())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.fell_at_s, None, "{:?}", r.steps);
        assert!(
            r.max_pitch_deg <= PITCH_BOUND_DEG,
            "pitch {}",
            r.max_pitch_deg
        );
        assert!(r.apex_max_error <= APEX_BAND, "apex {}", r.apex_max_error);
        assert_eq!(r.steps.len(), 4);
        for s in &r.steps {
            assert!(s.hops.is_some_and(|h| h <= SETTLE_HOPS), "{s:?}");
            let band = (0.1 * s.command_mps).max(SPEED_FLOOR_MPS);
            assert!(
                s.steady_mps
                    .is_some_and(|v| (v - s.command_mps).abs() <= band),
                "{s:?}"
            );
        }
        assert!(r.passes());
    }

    /// A 20 N s push on the body mid-stride, standing still: the speed is
    /// back within the band within 10 hops, and it does not fall.
    #[test]
    fn raibert_recovers_from_a_push() {
        let profile = SpeedProfile::parse("0:0").unwrap_or_else(|e| panic!("{e}"));
        let push = Push {
            at_s: 10.0,
            impulse_ns: 20.0,
        };
        let r = simulate(&profile, &[push], 25.0, RaibertConfig::table_2_2())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.fell_at_s, None);
        let p = r.pushes[0];
        assert!(p.hops.is_some_and(|h| h <= SETTLE_HOPS), "{p:?}");
        // It was pushed: the stride after it ran at over 0.5 m/s.
        assert!(
            r.strides
                .iter()
                .any(|s| s.t_s > push.at_s && s.speed_mps > 0.5),
            "{:?}",
            r.strides
        );
    }
}
