//! `mount` and `estop`: move the simulated robot (QEMU and `hopper-sim
//! serve` only; a real robot refuses).

use anyhow::Result;
use hopper_link::Client;
use hopper_protocol::Request;

/// `mount hoist|release`: clamp and lift the body until the toe is `toe`
/// above the ground, or let go.
pub(crate) fn mount(c: &mut Client, action: &str, toe: f32) -> Result<()> {
    c.expect_ok(Request::SimulateMount {
        hoisted: action == "hoist",
        lift_m: toe,
    })?;
    println!("mount: {action}");
    Ok(())
}

/// `estop press|release`: the simulated e-stop.
pub(crate) fn estop(c: &mut Client, action: &str) -> Result<()> {
    c.expect_ok(Request::SimulateEstop {
        pressed: action == "press",
    })?;
    println!(
        "simulated e-stop {}",
        if action == "press" {
            "pressed"
        } else {
            "released"
        }
    );
    Ok(())
}
