//! `hopper-sim planar serve`: the planar machine run by Raibert's
//! controller live, paced by the wall clock, and drawn in a browser as it
//! runs (the drawing of the recorded run's `run.html`, the same code), with
//! its speed against the command, its pitch and its strides.
//!
//! The page reads the run; it cannot command anything, so it needs no
//! token. It listens on the loopback interface unless told otherwise.

use anyhow::{bail, Context, Result};
use axum::extract::State;
use axum::http::{header, Uri};
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::Router;
use hal_sim::planar_raibert::{self as pr, PlanarRunSpec, SpeedProfile, Stride, Thrust};
use hal_sim::serve::{Queue, Served};
use hopper_sil::planar::{LegLaw, PlanarLoop, PlanarRobot, DT_S};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// At most this many frames in one answer (10 s of the run).
const FRAMES_PER_ANSWER: usize = 1000;

/// The run as far as the page has been told.
#[derive(Default)]
struct Live {
    /// Each frame as JSON, the speed command (m/s) after the drawing's
    /// seven numbers.
    frames: Vec<String>,
    strides: Vec<Stride>,
    /// How the run ended, once it has.
    done: Option<String>,
}

/// Serves the page on `addr` and runs `run` at `time_scale` times real
/// time; serves on after the run ends, until stopped.
pub(crate) fn serve(addr: &str, time_scale: f64, run: PlanarRunSpec) -> Result<()> {
    if !(time_scale.is_finite() && (0.01..=100.0).contains(&time_scale)) {
        bail!("--time-scale {time_scale} must be within 0.01 ..= 100");
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()
        .context("cannot start the page's server")?;
    let listener = rt
        .block_on(tokio::net::TcpListener::bind(addr))
        .with_context(|| format!("--http {addr}: cannot listen there"))?;
    let local = listener.local_addr()?;
    let live = Arc::new(Mutex::new(Live::default()));
    let shown = Arc::clone(&live);
    std::thread::spawn(move || simulate(run, time_scale, &shown));
    say!(
        "planar: http://{local}/ (the machine drawn live as it runs, at {time_scale}x real time; Ctrl-C stops)"
    );
    let app = Router::new()
        .route("/", get(page))
        .route("/frames", get(frames))
        .with_state(live);
    rt.block_on(async { axum::serve(listener, app).await })
        .context("the page's server stopped")?;
    Ok(())
}

/// The machine behind the host link, its speed command from the run's
/// profile, on robot time since it was let go.
struct Linked<L: LegLaw> {
    robot: PlanarRobot<L>,
    profile: SpeedProfile,
}

impl<L: LegLaw> Served for Linked<L> {
    fn period(&mut self, rx: Vec<u8>, tx: &mut Queue) -> Result<(), String> {
        let speed_mps = self.profile.at(self.robot.since_release_s());
        self.robot
            .period(rx, speed_mps, tx)
            .map(|_| ())
            .map_err(|e| format!("the planar machine failed: {e:?}"))
    }
}

/// Serves `run`'s machine behind the host link on `addr` at `time_scale`
/// times real time, for `run.duration_s` of robot time.
pub(crate) fn serve_link(addr: &str, time_scale: f64, run: PlanarRunSpec) -> Result<()> {
    if !(time_scale.is_finite() && (0.01..=100.0).contains(&time_scale)) {
        bail!("--time-scale {time_scale} must be within 0.01 ..= 100");
    }
    if !run.pushes.is_empty() {
        bail!("--inject is not for --tcp: the machine behind the link is pushed by nobody (`planar serve` without --tcp, or `planar run`, pushes it)");
    }
    run.check().map_err(anyhow::Error::msg)?;
    let lp = PlanarLoop::of(&run.machine, run.cfg, 0.0)
        .map_err(|e| anyhow::anyhow!("the planar machine cannot start: {e:?}"))?;
    let toe_m = f64::from(run.cfg.target_apex_m);
    let profile = run.profile.clone();
    let held = |e| anyhow::anyhow!("the planar machine cannot be held: {e:?}");
    let mut robot: Box<dyn Served> = match run.thrust {
        Thrust::Force => Box::new(Linked {
            robot: PlanarRobot::new(lp, toe_m).map_err(held)?,
            profile,
        }),
        Thrust::Screw(strategy) => {
            let lp = lp
                .with_screw(&strategy)
                .map_err(|e| anyhow::anyhow!("the leg's law cannot start: {e:?}"))?;
            Box::new(Linked {
                robot: PlanarRobot::new(lp, toe_m).map_err(held)?,
                profile,
            })
        }
    };
    let listener = std::net::TcpListener::bind(addr)
        .with_context(|| format!("--tcp {addr}: cannot listen there"))?;
    let local = listener.local_addr()?;
    say!(
        "hopper-sim: planar robot listening on {local} (Raibert's controller, the leg by {}, {time_scale}x real time, held {toe_m:.3} m up until armed, for {} s of robot time); connect with `hopper-link --tcp {local} ui`",
        match run.thrust {
            Thrust::Force => "force".to_string(),
            Thrust::Screw(s) => s.kind().name().to_string(),
        },
        run.duration_s
    );
    hal_sim::serve::serve_robot(
        robot.as_mut(),
        &listener,
        hal_sim::serve::ServeOptions {
            speed: time_scale,
            limit_s: Some(run.duration_s),
            dt_s: DT_S,
        },
    )
    .map_err(anyhow::Error::msg)
}

/// Runs the machine, each frame shown when the wall clock reaches its
/// time (over `time_scale`).
fn simulate(run: PlanarRunSpec, time_scale: f64, live: &Mutex<Live>) {
    let started = Instant::now();
    let (mut frames, mut strides) = (0, 0);
    let profile = &run.profile;
    let r = run.simulate_each(&mut |p| {
        if p.frames.len() == frames && p.strides.len() == strides {
            return;
        }
        if let Ok(mut l) = live.lock() {
            for f in &p.frames[frames..] {
                let drawn = pr::frame_json(f);
                l.frames.push(format!(
                    "{},{:.3}]",
                    drawn.trim_end_matches(']'),
                    profile.at(f[0])
                ));
            }
            l.strides.extend_from_slice(&p.strides[strides..]);
        }
        (frames, strides) = (p.frames.len(), p.strides.len());
        let due = Duration::from_secs_f64(p.t_s / time_scale);
        if let Some(wait) = due.checked_sub(started.elapsed()) {
            std::thread::sleep(wait);
        }
    });
    let done = match r {
        Ok(r) => match (&r.stopped_by, r.fell_at_s) {
            (Some(f), _) => format!("stopped at {:.2} s by the guard: {f}", r.duration_s),
            (None, Some(t)) => format!("fell at {t:.2} s"),
            (None, None) => format!(
                "ran {:.1} s, {} strides: {}",
                r.duration_s,
                r.strides.len(),
                if r.passes() {
                    "every figure within its bound"
                } else {
                    "a figure out of its bound (`hopper-sim planar run` prints which)"
                }
            ),
        },
        Err(e) => format!("could not run: {e}"),
    };
    if let Ok(mut l) = live.lock() {
        l.done = Some(done);
    }
}

/// `GET /`: the page.
async fn page() -> Html<String> {
    Html(PAGE.replace("/*DRAW*/", pr::PLANAR_DRAW_JS))
}

/// `GET /frames?from=N&strides=M`: the frames from the `N`th and the
/// strides from the `M`th, with how the run ended once it has:
/// `{"frames":[...],"strides":[...],"done":null}`.
async fn frames(State(live): State<Arc<Mutex<Live>>>, uri: Uri) -> impl IntoResponse {
    let arg = |key: &str| -> usize {
        uri.query()
            .unwrap_or("")
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .find(|(k, _)| *k == key)
            .and_then(|(_, v)| v.parse().ok())
            .unwrap_or(0)
    };
    let (from, from_stride) = (arg("from"), arg("strides"));
    let body = match live.lock() {
        Ok(l) => {
            let frames = l.frames.get(from..).unwrap_or(&[]);
            let frames = &frames[..frames.len().min(FRAMES_PER_ANSWER)];
            let strides = l.strides.get(from_stride..).unwrap_or(&[]);
            format!(
                "{{\"frames\":[{}],\"strides\":{},\"done\":{}}}",
                frames.join(","),
                serde_json::to_string(strides).unwrap_or_else(|_| "[]".into()),
                serde_json::to_string(&l.done).unwrap_or_else(|_| "null".into())
            )
        }
        Err(_) => "{\"frames\":[],\"strides\":[],\"done\":\"the run failed\"}".to_string(),
    };
    ([(header::CONTENT_TYPE, "application/json")], body)
}

/// The live page; `/*DRAW*/` is replaced by the drawing.
const PAGE: &str = r##"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>planar machine, live</title>
<style>body{font-family:sans-serif;margin:16px}svg{border:1px solid #ccc;background:#fafafa}#info{margin:6px 0;font-variant-numeric:tabular-nums}#done{color:#1b5e20;font-weight:bold}td,th{padding:1px 8px;text-align:right}</style>
</head><body>
<h3>The planar machine, hip actuated, run by Raibert's controller: live</h3>
<div id="info">waiting for the simulator</div>
<svg id="v" width="800" height="420" viewBox="0 0 800 420"></svg>
<div id="done"></div>
<p>Body: the bar, pitched by its angle; leg: hip to toe (thicker and red on the ground). The view follows the hip; ground marks every 0.5 m.</p>
<table><thead><tr><th>stride ends [s]</th><th>speed [m/s]</th><th>command [m/s]</th><th>toe apex [m]</th><th>pitch at most [deg]</th></tr></thead><tbody id="strides"></tbody></table>
<script>
/*DRAW*/
const v = document.getElementById("v"), info = document.getElementById("info");
let from = 0, sfrom = 0;
const recent = [];
function showStrides(list) {
  const body = document.getElementById("strides");
  for (const s of list) {
    const row = document.createElement("tr");
    row.innerHTML = `<td>${s.t_s.toFixed(2)}</td><td>${s.speed_mps.toFixed(3)}</td><td>${s.command_mps.toFixed(2)}</td><td>${s.apex_m.toFixed(3)}</td><td>${s.max_pitch_deg.toFixed(2)}</td>`;
    body.prepend(row);
    while (body.rows.length > 10) body.deleteRow(body.rows.length - 1);
  }
}
async function poll() {
  try {
    const m = await (await fetch(`/frames?from=${from}&strides=${sfrom}`)).json();
    from += m.frames.length; sfrom += m.strides.length;
    showStrides(m.strides);
    for (const f of m.frames) { recent.push(f); if (recent.length > 21) recent.shift(); }
    if (m.frames.length) {
      const f = recent[recent.length - 1], b = recent[0];
      drawPlanar(v, f);
      const speed = f[0] > b[0] ? (f[1] - b[1]) / (f[0] - b[0]) : 0;
      info.textContent = `t = ${f[0].toFixed(2)} s   speed ${speed.toFixed(2)} m/s (command ${f[7].toFixed(2)})   pitch ${(f[3] * 180 / Math.PI).toFixed(1)} deg   leg ${(f[4] * 180 / Math.PI).toFixed(1)} deg   ${sfrom} strides`;
    }
    if (m.done && m.frames.length === 0) { document.getElementById("done").textContent = m.done; return; }
  } catch (e) { info.textContent = `the simulator does not answer (${e})`; }
  setTimeout(poll, 40);
}
poll();
</script></body></html>
"##;
