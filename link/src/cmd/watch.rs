//! `watch`: a live status line.

use super::common::timing_of;
use anyhow::Result;
use hopper_link::{names, Client};
use hopper_protocol::{Request, RobotMsg};
use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

pub(crate) fn watch(c: &mut Client, duration: Option<f64>) -> Result<()> {
    let t = timing_of(c)?;
    let every = ((0.1 / f64::from(t.period_s)).round() as u16).max(1);
    c.discard_events();
    c.expect_ok(Request::Telemetry { every })?;
    c.discard_queued();
    let tty = std::io::stdout().is_terminal();
    let start = Instant::now();
    let mut last_apex = f32::NAN;
    let mut last_seq: Option<u32> = None;
    let mut drops: u64 = 0;
    let mut state = String::from("?");
    while duration.is_none_or(|d| start.elapsed().as_secs_f64() < d) {
        match c.next_event(Duration::from_millis(500))? {
            Some(RobotMsg::Telemetry(r)) => {
                drops += u64::from(hopper_link::seq_gap(last_seq, r.seq));
                last_seq = Some(r.seq);
                let line = format!(
                    "{:<22} faults {:<16} apex {:>7.4} m  z {:.4} m  nut {:>6.2} mm  F {:>6.1} N  I {:>6.2} A  drops {}",
                    if r.armed { "armed".to_string() } else { state.clone() },
                    names::faults(r.faults),
                    last_apex,
                    r.body_height_m,
                    r.nut_position_m * 1000.0,
                    r.spring_force_n,
                    r.command_a,
                    drops
                );
                show(&line, tty, r.seq);
            }
            Some(RobotMsg::Planar(r)) => {
                drops += u64::from(hopper_link::seq_gap(last_seq, r.seq));
                last_seq = Some(r.seq);
                let line = format!(
                    "{:<22} guard {:<19} x {:>7.3} m  z {:.4} m  pitch {:>6.2} deg  speed {:>6.3} m/s (command {:.2})  hip {:>6.2} A  leg {:>6.2} A  drops {}",
                    if r.armed { "armed".to_string() } else { state.clone() },
                    super::status::planar_fault(r.fault),
                    r.x_m,
                    r.z_m,
                    r.pitch_rad.to_degrees(),
                    r.speed_mps,
                    r.speed_command_mps,
                    r.hip_current_a,
                    r.leg_current_a,
                    drops
                );
                show(&line, tty, r.seq);
            }
            Some(RobotMsg::Hop(h)) => last_apex = h.apex_height_m,
            Some(RobotMsg::State(s)) => state = names::arm_state(s),
            Some(RobotMsg::Faults { step, bits }) => {
                println!("\nfault at step {step}: {}", names::faults(bits));
            }
            _ => {}
        }
    }
    c.expect_ok(Request::Telemetry { every: 0 })?;
    if tty {
        println!();
    }
    Ok(())
}

/// The status line: in place on a terminal, every tenth otherwise.
fn show(line: &str, tty: bool, seq: u32) {
    if tty {
        print!("\r{line}");
    } else if seq.is_multiple_of(10) {
        println!("{line}");
    }
    let _ = std::io::stdout().flush();
}
