//! The kernel estimator ([`Estimator::Kernel`](super::Estimator::Kernel), a departure from the seed): the exit
//! distribution from each wall position tabulated once, added per entry by its first hit.

use super::{
    bin_centre, entry_point, first_hit, incident_dir, ConvexDiffuse, TraceError, TraceOutput,
    TraceSettings, KERNEL_NODES,
};
use crate::hash::mix64;
use crate::precompute::cross_section::CrossSection;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Salt of the kernel walks' random streams (distinct from the entry streams).
const KERNEL_SALT: u64 = 0x4B45_524E_454C_0001;

/// [`Estimator::Kernel`](super::Estimator::Kernel): tabulate the kernel of every wall, then give each entry point the
/// interpolated kernel row of its first hit. Fresnel mode `Seed` and diffuse walls (checked
/// by `validate`); the groove must be convex.
pub(super) fn trace_kernel(
    geo: &CrossSection,
    s: &TraceSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput, TraceError> {
    if !geo.convex {
        return Err(TraceError::BadParameter {
            key: "estimator",
            value: "kernel".into(),
            why: "the kernel estimator needs a convex groove profile (V, round, trapezoid, \
                  flat or a convex polyline)",
        });
    }
    let m = s.m;
    let (nodes, nseg) = (KERNEL_NODES, geo.segs.len());
    let node_weights: Vec<Vec<f64>> = (0..m)
        .into_par_iter()
        .map(|row| kernel_node_weights(geo, s, row))
        .collect();
    // Walks per node: `W_n = N N_r max_i(w_in / N)`. Then each row's kernel variance,
    // `sum_n (w_in / N)^2 var_n / W_n <= sum_n (w_in / N) var / (N N_r)`, is at most what
    // the N_r scheme's walks give (grazing rows, whose first hits crowd into a few nodes
    // near a wall's top, get those nodes densely sampled). At least 64 walks per node.
    let paths = s.n as f64 * s.nr as f64;
    let walks_per_node: Vec<usize> = (0..nseg * nodes)
        .map(|id| {
            let max_w = node_weights.iter().map(|w| w[id]).fold(0.0f64, f64::max);
            ((paths * max_w / s.n as f64).ceil() as usize).clamp(64, s.n * s.nr)
        })
        .collect();
    let kernel = kernel_rows(&ConvexDiffuse::new(geo, s), &walks_per_node, progress);
    // Each row: its node weights times the kernel rows.
    let phi_rows: Vec<Vec<f64>> = node_weights
        .par_iter()
        .map(|node_w| {
            let mut acc = vec![0.0; m + 2];
            for (w, krow) in node_w.iter().zip(&kernel) {
                if *w != 0.0 {
                    for (a, kv) in acc.iter_mut().zip(krow) {
                        *a += w * kv;
                    }
                }
            }
            acc[m + 1] += node_w[nseg * nodes];
            acc
        })
        .collect();
    let norm: Vec<f64> = (0..m)
        .map(|j| m as f64 / (PI * s.n as f64 * bin_centre(j, m).cos()))
        .collect();
    let mut out = TraceOutput {
        m,
        rho_m: vec![0.0; m * m],
        rho_walls: None,
        dropped: vec![0.0; m],
        lost: vec![0.0; m],
    };
    for (row, acc) in phi_rows.iter().enumerate() {
        for j in 0..m {
            out.rho_m[row * m + j] = acc[j] * norm[j];
        }
        out.dropped[row] = acc[m] / s.n as f64;
        out.lost[row] = acc[m + 1] / s.n as f64;
    }
    Ok(out)
}

/// Row `row`'s entry weights per kernel node (first hits, linear interpolation in the position
/// along the wall), and its lost entries (last element).
fn kernel_node_weights(geo: &CrossSection, s: &TraceSettings, row: usize) -> Vec<f64> {
    let (nodes, nseg) = (KERNEL_NODES, geo.segs.len());
    let d0 = incident_dir(row, s.m);
    let mut node_w = vec![0.0; nseg * nodes + 1];
    for k in 0..s.n {
        let (o, _) = entry_point(s, row, k);
        let Some((seg0, hit0)) = first_hit(geo, o, d0) else {
            node_w[nseg * nodes] += 1.0;
            continue;
        };
        let sg = &geo.segs[seg0];
        let e2 = sg.e[0] * sg.e[0] + sg.e[1] * sg.e[1];
        let u = ((hit0[0] - sg.p[0]) * sg.e[0] + (hit0[1] - sg.p[1]) * sg.e[1]) / e2;
        let f = u * nodes as f64 - 0.5;
        let i0 = (f.floor().max(0.0) as usize).min(nodes - 2);
        let frac = (f - i0 as f64).clamp(0.0, 1.0);
        // The first hit's weight: the facet albedo (no Fresnel in `Seed` mode).
        node_w[seg0 * nodes + i0] += (1.0 - frac) * s.albedo;
        node_w[seg0 * nodes + i0 + 1] += frac * s.albedo;
    }
    node_w
}

/// The kernel row of node `i` of wall `seg` (index `seg * nodes + i`): the exit histogram per
/// walk started by a diffuse bounce there (its hit already counted), then the dropped and the
/// lost fractions.
fn kernel_rows(
    convex: &ConvexDiffuse,
    walks_per_node: &[usize],
    progress: &(dyn Fn(u64) + Sync),
) -> Vec<Vec<f64>> {
    let (s, geo, nodes) = (convex.s, convex.geo, KERNEL_NODES);
    let kernel_walks: u64 = walks_per_node.iter().map(|&w| w as u64).sum();
    (0..geo.segs.len() * nodes)
        .into_par_iter()
        .map(|id| {
            let (seg, node) = (id / nodes, id % nodes);
            let sg = &geo.segs[seg];
            let u = (node as f64 + 0.5) / nodes as f64;
            let pos = [sg.p[0] + u * sg.e[0], sg.p[1] + u * sg.e[1]];
            let key = mix64(mix64(s.seed ^ KERNEL_SALT) ^ (((seg as u64) << 32) | node as u64));
            let walks = walks_per_node[id];
            let mut row = vec![0.0; s.m + 2];
            for r in 0..walks {
                convex.kernel_walk(key, r, pos, seg, &mut row);
            }
            for v in row.iter_mut() {
                *v /= walks as f64;
            }
            progress((walks as u64 * s.total_paths()).div_ceil(kernel_walks.max(1)));
            row
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::{trace, Estimator, FresnelMode, Walls};
    use super::*;
    use crate::precompute::profile::Profile;

    /// The kernel estimator has the expectation of the `N_r` scheme: per bin, the difference
    /// is within the two estimates' Monte Carlo error (binomial per walk); it conserves
    /// energy exactly (rows sum to the albedo of the walks); it is deterministic.
    #[test]
    fn kernel_estimator_agrees_with_walks() {
        for (spec, albedo) in [("v:angle=90", 1.0), ("round:depth=0.4", 0.8)] {
            let p = Profile::parse(spec).unwrap();
            let s = TraceSettings {
                m: 16,
                n: 1000,
                nr: 64,
                albedo,
                seed: 3,
                ..TraceSettings::default()
            };
            let k = TraceSettings {
                estimator: Estimator::Kernel,
                ..s.clone()
            };
            let walks = trace(&p, &s, &|_| {}).unwrap();
            let kernel = trace(&p, &k, &|_| {}).unwrap();
            let m = s.m;
            let paths = (s.n * s.nr) as f64;
            let (mut max_z, mut sum_z2, mut count) = (0.0f64, 0.0, 0);
            for i in 0..m {
                // Fraction of the incident energy in bin j.
                let frac =
                    |rho: &[f64], j: usize| rho[i * m + j] * bin_centre(j, m).cos() * PI / m as f64;
                for j in 0..m {
                    let (fw, fk) = (frac(&walks.rho_m, j), frac(&kernel.rho_m, j));
                    let f = 0.5 * (fw + fk);
                    if f <= 0.0 {
                        continue;
                    }
                    // Walk weights are at most 1: binomial variance bounds each estimate's.
                    let sigma = (2.0 * f * (1.0 - f).max(0.0) / paths).sqrt();
                    let z = (fw - fk) / sigma;
                    max_z = max_z.max(z.abs());
                    sum_z2 += z * z;
                    count += 1;
                }
                if albedo == 1.0 {
                    let total: f64 = (0..m).map(|j| frac(&kernel.rho_m, j)).sum();
                    assert!(
                        (total + kernel.dropped[i] - 1.0).abs() < 1e-9,
                        "{spec} row {i}: {total} + {}",
                        kernel.dropped[i]
                    );
                }
                assert_eq!(kernel.lost[i], 0.0);
            }
            let mean_z2 = sum_z2 / count as f64;
            assert!(max_z < 5.0, "{spec}: max |z| {max_z}");
            assert!(mean_z2 < 2.0, "{spec}: mean z^2 {mean_z2}");
            // And it is a different estimate, not a copy.
            assert_ne!(walks.rho_m, kernel.rho_m);
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| trace(&p, &k, &|_| {}).unwrap());
            assert_eq!(one, kernel, "{spec}: thread-count dependent");
        }
    }

    #[test]
    fn kernel_estimator_refuses_inexact_cases() {
        let k = TraceSettings {
            m: 8,
            n: 50,
            nr: 4,
            estimator: Estimator::Kernel,
            ..TraceSettings::default()
        };
        let v = Profile::parse("v:angle=90").unwrap();
        for s in [
            TraceSettings {
                walls: Walls::Specular,
                ..k.clone()
            },
            TraceSettings {
                fresnel_mode: FresnelMode::Walls,
                ..k.clone()
            },
        ] {
            let e = trace(&v, &s, &|_| {}).unwrap_err();
            assert!(e.to_string().contains("estimator"), "{e}");
        }
        let w = Profile::w_groove();
        let e = trace(&w, &k, &|_| {}).unwrap_err();
        assert!(e.to_string().contains("convex"), "{e}");
        assert!(trace(&v, &k, &|_| {}).is_ok());
    }
}
