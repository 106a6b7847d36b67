//! How fast can the hopper climb at all? A bang-bang nut schedule with
//! perfect knowledge of the plant's state (no sensors, no estimator), on the
//! full plant model: per hop, push (+I) from touchdown for `a` of the model
//! stance time, reverse (-I) until `b` of the predicted flight time has
//! passed, then push again until touchdown (the structure of the best nut
//! cycle in docs/beat-the-thesis.md). Scans `a` x `b` and prints, for each,
//! the hop at which the apex first reaches 98 % of the target: once
//! reversing at full current into the upper stop, once braking so that the
//! nut reaches it at no speed (as the `shaped` law's back-drive does). A
//! yardstick for the closed-loop law, which has only its sensors.
//!
//! ```sh
//! cargo run --release -p hal-sim --example bang_bang_climb [PARAMS] [START] [TARGET]
//! ```
#![allow(missing_docs)]

use hal_sim::plant::Ledger;
use hal_sim::{Event, Params, Plant};

const DT_S: f64 = 1e-4;

/// Apexes of a run of the schedule (m), and the plant's energy ledger.
fn climb(p: &Params, start_m: f64, a: f64, b: f64, soft: bool, hops: usize) -> (Vec<f64>, Ledger) {
    let mut plant = match Plant::new(*p, start_m) {
        Ok(pl) => pl,
        Err(e) => panic!("{e}"),
    };
    let i_max = p.current_limit_a;
    let m_t = p.body_mass_kg + p.nut_mass_kg + p.unsprung_mass_kg;
    let g_up = p.gravity_mps2 + p.planarizer_friction_n / m_t;
    let g_dn = p.gravity_mps2 - p.planarizer_friction_n / m_t;
    let t_stance = core::f64::consts::PI
        * ((p.body_mass_kg + p.nut_mass_kg) / p.spring_stiffness_n_per_m).sqrt();
    // Flight time for an apex of h above the touchdown height.
    let flight = |h: f64| (2.0 * h / g_up).sqrt() + (2.0 * h / g_dn).sqrt();
    // Released at rest at the apex: the push starts (b - 1/2) of a flight
    // after the apex.
    let mut push_until = f64::NEG_INFINITY;
    let mut reverse_until = (b - 0.5) * flight(start_m);
    let mut apexes = Vec::new();
    let mut in_stance = false;
    let mut events = Vec::new();
    while apexes.len() < hops && plant.time_s() < 20.0 {
        let t = plant.time_s();
        let s = plant.state();
        let mut cmd = if t < push_until {
            i_max
        } else if t < reverse_until || in_stance {
            -i_max
        } else {
            i_max
        };
        // Keep off the lower stop: brake when it could not stop in time.
        let decel = p.efficiency * p.torque_constant_nm_per_a * i_max
            / p.screw_m_per_rad()
            / p.reflected_inertia_kg();
        if s.pd_mps > 0.0 && s.p_m + s.pd_mps * s.pd_mps / (2.0 * decel) > 0.9 * p.stroke_m {
            cmd = -i_max;
        }
        // `soft`: also keep off the upper stop, braking (+I, less the
        // spring's push) so the nut arrives there at no speed.
        if soft && s.pd_mps < 0.0 {
            let spring_n = p.spring_stiffness_n_per_m * (p.spring_preload_m + s.p_m);
            let up_decel =
                (decel * p.reflected_inertia_kg() - spring_n).max(1.0) / p.reflected_inertia_kg();
            if s.pd_mps * s.pd_mps / (2.0 * up_decel) >= 0.9 * s.p_m {
                cmd = i_max;
            }
        }
        events.clear();
        if let Err(e) = plant.advance(DT_S, cmd, &mut |e| events.push(e)) {
            panic!("{e}");
        }
        for &e in &events {
            match e {
                Event::Touchdown { t_s, .. } => {
                    in_stance = true;
                    push_until = t_s + a * t_stance;
                    reverse_until = f64::INFINITY;
                }
                Event::Liftoff {
                    t_s, zd_after_mps, ..
                } => {
                    in_stance = false;
                    let v = zd_after_mps.max(0.0);
                    let h = v * v / (2.0 * g_up);
                    reverse_until = t_s + v / g_up + (b - 0.5) * flight(h);
                }
                Event::Apex { toe_height_m, .. } => apexes.push(toe_height_m),
                _ => {}
            }
        }
    }
    (apexes, *plant.ledger())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("design", String::as_str);
    let Some(p) = Params::preset(name) else {
        panic!("unknown preset {name}: design or identified")
    };
    let num = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let start = num(2, 0.05);
    let target = num(3, 0.15);
    for soft in [false, true] {
        scan(&p, start, target, soft);
    }
}

fn scan(p: &Params, start: f64, target: f64, soft: bool) {
    println!(
        "\n{}",
        if soft {
            "braking so that the nut reaches the upper stop at no speed:"
        } else {
            "reversing at full current into the upper stop:"
        }
    );
    let mut best: Option<(usize, f64, f64, Vec<f64>)> = None;
    println!("a \\ b: hop at which the apex first reaches 98 % of {target} m (- = not in 30 hops)");
    let bs: Vec<f64> = (0..=15).map(|j| 0.2 + 0.05 * j as f64).collect();
    print!("     ");
    for b in &bs {
        print!("{b:5.2}");
    }
    println!();
    for i in 0..=12 {
        let a = 0.3 + 0.05 * i as f64;
        print!("{a:5.2}");
        for &b in &bs {
            let (ap, _) = climb(p, start, a, b, soft, 30);
            match ap.iter().position(|&h| h >= 0.98 * target) {
                Some(n) => {
                    print!("{:5}", n + 1);
                    if best.as_ref().is_none_or(|x| n + 1 < x.0) {
                        best = Some((n + 1, a, b, ap.clone()));
                    }
                }
                None => print!("    -"),
            }
        }
        println!();
    }
    if let Some((n, a, b, ap)) = best {
        let shown: Vec<String> = ap.iter().take(n + 3).map(|h| format!("{h:.4}")).collect();
        println!(
            "best: a={a:.2} b={b:.2}, hop {n}: apexes {}",
            shown.join(" ")
        );
        let (_, l) = climb(p, start, a, b, soft, n);
        println!(
            "over those {n} hops, J: motor work {:.1}, friction {:.1}, touchdown {:.1}, liftoff {:.1}, stop impacts {:.1}",
            l.motor_work_j, l.friction_j, l.touchdown_loss_j, l.liftoff_loss_j, l.stop_impact_loss_j
        );
    }
}
