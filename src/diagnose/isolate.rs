//! Isolation in the space of what the measurements see (rule I1 of `docs/diagnosis.md`).
//!
//! Each actuator's estimated deviation `e_j` maps to an effect on the measurements through its
//! weighted effect per step `b_j` (rows of `[p, q, r(, a_z)]` divided by their noise):
//! `v = Σ_j b_j e_j`. Orthogonal matching pursuit then explains `v`: the actuator whose effect
//! explains the most energy of what is left joins, all joined are refitted together (normal
//! equations), and a further one joins only with a share of at least `explain_min` and an
//! effect largely its own (at least a quarter of its squared norm independent of those joined).
//! So a deviation the measurements cannot see (a helicopter's collective with the tail's
//! compensation, a hexacopter's opposite motor pairs) never looks like one actuator's fault,
//! and a lone fault is attributed whole to its actuator.

use crate::model::MAX_ACTUATORS;

/// Weight of a motor's positive share (more thrust than commanded) in the choice of who
/// explains the measurements: the prior that motors fail low. It only matters where two
/// explanations fit equally (a hexacopter motor's loss against its opposite's excess).
const MOTOR_EXCESS_PRIOR: f64 = 0.5;

/// Squared fraction of a further actuator's effect that must be independent of the effects
/// already joined (0.25: half its norm). Two nearly opposite motors fitted together can make
/// almost any thrust-only pattern with large cancelling deviations, which is how model error
/// looks.
const MIN_OWN_FRACTION: f64 = 0.25;

/// At most this many actuators are fitted together.
const MAX_JOINED: usize = 4;

/// The attribution's fixed data: effects, which actuators are motors, and the smallest share.
#[derive(Debug, Clone)]
pub struct Isolation {
    pub effects: Vec<[f64; 4]>,
    pub is_motor: Vec<bool>,
    /// Motors when there are at least three (their common deviation is thrust mismatch).
    pub motors: Vec<usize>,
    pub explain_min: f64,
}

fn dot(a: &[f64; 4], c: &[f64; 4]) -> f64 {
    (0..4).map(|i| a[i] * c[i]).sum()
}

fn share(bj: &[f64; 4], r: &[f64; 4]) -> f64 {
    let n = dot(bj, bj);
    if n > 0.0 { dot(bj, r) / n } else { 0.0 }
}

impl Isolation {
    /// Three or more motors moving together is thrust mismatch (a payload, a sagging battery,
    /// a profile that overstates effectiveness), not one motor's fault: their median is taken
    /// out.
    pub fn without_thrust_mismatch(&self, r: &[f64; MAX_ACTUATORS]) -> [f64; MAX_ACTUATORS] {
        let mut e = *r;
        if self.motors.is_empty() {
            return e;
        }
        let mut m = [0.0; MAX_ACTUATORS];
        for (slot, &j) in m.iter_mut().zip(&self.motors) {
            *slot = r[j];
        }
        let m = &mut m[..self.motors.len()];
        m.sort_by(f64::total_cmp);
        let n = m.len();
        let median = if n % 2 == 1 {
            m[n / 2]
        } else {
            0.5 * (m[n / 2 - 1] + m[n / 2])
        };
        for &j in &self.motors {
            e[j] -= median;
        }
        e
    }

    /// Attribute the deviations `e` (one per actuator) into `out`: joined actuators get their
    /// fitted deviation, the others their share of what is left. `preferred` (the actuator the
    /// change test names) joins first if its share is at least `explain_min`.
    pub fn explain(&self, e: &[f64], out: &mut [f64], preferred: Option<usize>) {
        let l = e.len();
        let b = &self.effects;
        let mut v = [0.0; 4];
        for (bj, ej) in b.iter().zip(e) {
            for i in 0..4 {
                v[i] += bj[i] * ej;
            }
        }
        if v == [0.0; 4] {
            out.fill(0.0);
            return;
        }
        let mut joined = [0usize; MAX_JOINED];
        let mut basis = [[0.0; 4]; MAX_JOINED];
        let mut x = [0.0; MAX_JOINED];
        let mut k = 0;
        let mut rest = v;
        while k < MAX_JOINED.min(l) {
            let energy = |j: usize, sj: f64| -> f64 {
                let e = sj * sj * dot(&b[j], &b[j]);
                if sj > 0.0 && self.is_motor[j] {
                    e * MOTOR_EXCESS_PRIOR
                } else {
                    e
                }
            };
            let first = preferred
                .filter(|&p| k == 0 && p < l)
                .map(|p| (p, share(&b[p], &rest)))
                .filter(|(_, sp)| sp.abs() >= self.explain_min);
            let cand = first.or_else(|| {
                (0..l)
                    .filter(|j| !joined[..k].contains(j))
                    .map(|j| (j, share(&b[j], &rest)))
                    .max_by(|p, q| energy(p.0, p.1).total_cmp(&energy(q.0, q.1)))
            });
            let Some((j, sj)) = cand else { break };
            if sj.abs() < self.explain_min {
                break;
            }
            let mut own = b[j];
            for q in &basis[..k] {
                let c = dot(q, &b[j]);
                for i in 0..4 {
                    own[i] -= c * q[i];
                }
            }
            let own_sq = dot(&own, &own);
            if own_sq < MIN_OWN_FRACTION * dot(&b[j], &b[j]) {
                break;
            }
            let norm = own_sq.sqrt();
            for i in 0..4 {
                basis[k][i] = own[i] / norm;
            }
            joined[k] = j;
            k += 1;
            let mut a = [[0.0; MAX_JOINED + 1]; MAX_JOINED];
            for r in 0..k {
                for c in 0..k {
                    a[r][c] = dot(&b[joined[r]], &b[joined[c]]);
                }
                a[r][k] = dot(&b[joined[r]], &v);
            }
            let Some(sol) = solve_small(&mut a, k) else {
                k -= 1;
                break;
            };
            x[..k].copy_from_slice(&sol[..k]);
            rest = v;
            for (r, &jr) in joined[..k].iter().enumerate() {
                for i in 0..4 {
                    rest[i] -= b[jr][i] * x[r];
                }
            }
        }
        for (j, o) in out.iter_mut().enumerate() {
            *o = match joined[..k].iter().position(|&q| q == j) {
                Some(r) => x[r],
                None => share(&b[j], &rest),
            };
        }
    }
}

/// Solve the `k`×`k` system in `a` (augmented with the right-hand side in column `k`) by
/// Gaussian elimination with partial pivoting; `None` when it is (nearly) singular.
fn solve_small<const C: usize>(a: &mut [[f64; C]; 4], k: usize) -> Option<[f64; 4]> {
    let scale = (0..k).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for col in 0..k {
        let piv = (col..k).max_by(|&p, &q| a[p][col].abs().total_cmp(&a[q][col].abs()))?;
        if a[piv][col].abs().is_nan() || a[piv][col].abs() <= 1e-9 * scale {
            return None;
        }
        a.swap(col, piv);
        let pivot_row = a[col];
        for row in a[col + 1..k].iter_mut() {
            let f = row[col] / pivot_row[col];
            for (v, p) in row[col..=k].iter_mut().zip(&pivot_row[col..=k]) {
                *v -= f * p;
            }
        }
    }
    let mut x = [0.0; 4];
    for r in (0..k).rev() {
        let mut acc = a[r][k];
        for c in r + 1..k {
            acc -= a[r][c] * x[c];
        }
        x[r] = acc / a[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::telemetry::Profile;

    fn isolation(profile: &str) -> Isolation {
        let p = Profile::resolve(profile).unwrap();
        let effects = crate::estimate::vehicle::weighted_effects(&p, 0.02);
        let is_motor: Vec<bool> = (p.actuators.iter())
            .map(|a| a.role == crate::telemetry::Role::Motor)
            .collect();
        let motors: Vec<usize> = (0..is_motor.len()).filter(|&j| is_motor[j]).collect();
        Isolation {
            effects,
            is_motor,
            motors: if motors.len() >= 3 { motors } else { vec![] },
            explain_min: 0.04,
        }
    }

    #[test]
    fn a_lone_deviation_is_attributed_whole_to_its_actuator() {
        for profile in ["quad-x", "hexa-x", "heli-h3-120", "plane"] {
            let iso = isolation(profile);
            let l = iso.effects.len();
            for j in 0..l {
                let mut e = [0.0; MAX_ACTUATORS];
                e[j] = -0.2;
                let mut out = [0.0; MAX_ACTUATORS];
                iso.explain(&e[..l], &mut out[..l], None);
                for (k, o) in out[..l].iter().enumerate() {
                    let want = if k == j { -0.2 } else { 0.0 };
                    assert!((o - want).abs() < 1e-9, "{profile} {j}: {k} got {o}");
                }
            }
        }
    }

    #[test]
    fn opposite_motors_together_are_not_one_motors_fault_and_a_common_one_is_mismatch() {
        let iso = isolation("hexa-x");
        // Motors 5 and 6 of the hexa X sit on opposite arms with opposite spin: both short
        // by the same amount is a thrust-only pattern, which any opposite pair fits. Without
        // the rule that a further actuator needs an effect of its own, the pair would be
        // fitted at the full -0.6 each; with it, one motor gets only its single share.
        let mut out = [0.0; MAX_ACTUATORS];
        iso.explain(&[0.0, 0.0, 0.0, 0.0, -0.6, -0.6], &mut out[..6], None);
        assert!(out[..6].iter().all(|o| o.abs() < 0.15), "{out:?}");
        let common = iso.without_thrust_mismatch(&[0.05; MAX_ACTUATORS]);
        assert!(common[..6].iter().all(|v| v.abs() < 1e-12));
    }

    #[test]
    fn small_systems_solve_exactly_and_singular_ones_are_refused() {
        let mut a = [[2.0, 1.0, 3.0], [1.0, 3.0, 5.0], [0.0; 3], [0.0; 3]];
        let x = solve_small(&mut a, 2).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12);
        let mut s = [[1.0, 2.0, 1.0], [2.0, 4.0, 2.0], [0.0; 3], [0.0; 3]];
        assert!(solve_small(&mut s, 2).is_none());
    }
}
