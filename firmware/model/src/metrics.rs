//! Hop metrics: the project's one definition of a steady apex and of
//! convergence, shared by the QEMU firmware images, the simulator (through
//! `hopper_plant::metrics`) and `hopper-link` (`no_std`).

/// Mean of the last 5 apexes if they agree within 2% (of the largest), m.
pub fn steady_apex(apexes: &[f64]) -> Option<f64> {
    let n = apexes.len();
    if n < 5 {
        return None;
    }
    let last = apexes.get(n - 5..)?;
    let max = last.iter().copied().fold(f64::MIN, f64::max);
    let min = last.iter().copied().fold(f64::MAX, f64::min);
    (max > 0.0 && max - min <= 0.02 * max).then(|| last.iter().sum::<f64>() / 5.0)
}

/// Hops to converge: the 1-based index of the first apex from which all
/// later apexes are within `tol` (relative) of `target`, requiring at least
/// 3 such apexes; `None` if never.
pub fn hops_to_converge(apexes: &[f64], target: f64, tol: f64) -> Option<usize> {
    if target.is_nan() || target <= 0.0 {
        return None;
    }
    let within = |h: &f64| (h - target).abs() <= tol * target;
    let tail = apexes.iter().rev().take_while(|h| within(h)).count();
    (tail >= 3).then(|| apexes.len() - tail + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convergence_needs_a_tail_of_three() {
        let t = 0.05;
        assert_eq!(
            hops_to_converge(&[0.02, 0.04, 0.0495, 0.0501, 0.05], t, 0.02),
            Some(3)
        );
        assert_eq!(
            hops_to_converge(&[0.02, 0.0495, 0.06, 0.0501, 0.05], t, 0.02),
            None
        );
        assert_eq!(hops_to_converge(&[0.05, 0.05, 0.05], 0.0, 0.02), None);
        assert_eq!(
            steady_apex(&[0.1, 0.05, 0.05, 0.05, 0.05, 0.05]),
            Some(0.05)
        );
        assert_eq!(steady_apex(&[0.05, 0.05, 0.05, 0.05]), None);
    }
}
