//! The element loop of the incremental potential for St. Venant-Kirchhoff (the integrators'
//! `evaluate`, `integrate/potential.rs`), four tetrahedra side by side in lanes: per element the
//! energy `V psi(E)` and elastic nodal forces of eq. (12-22), `det F`, and, when damped, the step
//! dissipation and viscous forces of `fem/viscous.rs` (its one-element references are
//! [`super::tet4::elastic_energy_forces`] and [`super::viscous::step_dissipation`]; a unit test
//! holds the loop to them).
//!
//! The law is the one of [`crate::material::linear`], written over its `Scalar` trait, here for
//! a lane type of four `f64` ([`L4`]). On an x86-64 CPU with AVX2 and FMA (detected at run time,
//! and allowed by [`crate::meshfree::set_simd_enabled`], the one switch of the crate's SIMD
//! copies) the loop is compiled for those features, where a lane operation is one instruction
//! and `a * b + c` one fused multiply-add; elsewhere the same loop runs portably (`a * b + c`
//! unfused). The two differ by round-off.
//!
//! Why: one element at a time, the 3x3 algebra of a tet (about 350 flops) left the SIMD units
//! idle; the element loop had 10% of the samples of a Rodero hybrid tick (900 damped core tets),
//! 6.6% in lanes (docs/history/benchmarks-log.md#third-session-2026-11-26-7-10-off-the-rodero-tick-why-the-rest-is-not-in-tuning).
//! The protocol's full-FEM step is set by its
//! factored solve, not by this loop, and did not change.
//!
//! `unsafe` here is one call: entering the AVX2 + FMA compiled copy after checking that the CPU
//! has both (the crate's second audited place, beside `meshfree/pair_loop/avx2.rs`).

use crate::fem::TetRest;
use crate::material::linear::{det3, green_strain_of, mm, Scalar, Svk, M3};
use crate::math::Vec3;

/// Four values side by side; `FMA`: `madd` is fused (only in the AVX2 + FMA copy, where it is
/// one instruction; elsewhere a fused multiply-add would be a library call).
#[derive(Clone, Copy)]
pub(crate) struct L4<const FMA: bool>([f64; 4]);

// Plain loops, not `array::from_fn` closures: a closure is compiled apart from the AVX2 + FMA
// function it sits in, without its features (measured: `mul_add` became a library call and the
// loop ran 1.8x slower than one element at a time).
impl<const FMA: bool> Scalar for L4<FMA> {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        L4([x; 4])
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        let mut r = self.0;
        for l in 0..4 {
            r[l] += o.0[l];
        }
        L4(r)
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut r = self.0;
        for l in 0..4 {
            r[l] -= o.0[l];
        }
        L4(r)
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut r = self.0;
        for l in 0..4 {
            r[l] *= o.0[l];
        }
        L4(r)
    }
    #[inline(always)]
    fn madd(self, b: Self, c: Self) -> Self {
        let mut r = c.0;
        for l in 0..4 {
            r[l] = if FMA { self.0[l].mul_add(b.0[l], c.0[l]) } else { self.0[l] * b.0[l] + c.0[l] };
        }
        L4(r)
    }
}

/// What the element loop sums: elastic energy `W` \[J\], dissipation `D` \[J\], the force-size
/// estimate `sum W k` (see `potential.rs`), and the count of elements with `det F <= 0`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ElementSums {
    pub w: f64,
    pub d: f64,
    pub f2: f64,
    pub inverted: usize,
}

/// The loop's inputs: the elements, their rest data and stiffness estimates, the law, and the
/// step (`x_n` and `h`) when the viscous terms are wanted.
pub(crate) struct ElementLoop<'a> {
    pub tets: &'a [[usize; 4]],
    pub rest: &'a [TetRest],
    pub stiffness: &'a [f64],
    pub law: Svk,
    /// `(phi, psi)` \[Pa s\] and `(x_n, h)`: the step's start and length, when damped.
    pub viscous: Option<((f64, f64), &'a [Vec3], f64)>,
}

impl ElementLoop<'_> {
    /// Elastic forces into `f_el` and, when damped, viscous forces into `f_visc` (both added to:
    /// the caller zeroes them), at positions `x` \[m\]; the sums.
    pub(crate) fn run(&self, x: &[Vec3], f_el: &mut [Vec3], f_visc: &mut [Vec3]) -> ElementSums {
        self.run_copy(crate::meshfree::simd_allowed(), x, f_el, f_visc)
    }

    /// [`Self::run`] in the AVX2 + FMA copy when `simd` and the CPU has both, else portably.
    fn run_copy(&self, simd: bool, x: &[Vec3], f_el: &mut [Vec3], f_visc: &mut [Vec3]) -> ElementSums {
        #[cfg(target_arch = "x86_64")]
        if simd && is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            // SAFETY: a `target_feature` function needs only that the CPU has the features,
            // checked on the line above.
            #[allow(unsafe_code)]
            return unsafe { run_avx2(self, x, f_el, f_visc) };
        }
        run_lanes::<false>(self, x, f_el, f_visc)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2(l: &ElementLoop<'_>, x: &[Vec3], f_el: &mut [Vec3], f_visc: &mut [Vec3]) -> ElementSums {
    run_lanes::<true>(l, x, f_el, f_visc)
}

/// `Ds` (columns `p_1 - p_0`, `p_2 - p_0`, `p_3 - p_0`) of the four elements `t` at positions
/// `x`, in lanes.
#[inline(always)]
fn ds<const FMA: bool>(x: &[Vec3], t: &[[usize; 4]; 4]) -> M3<L4<FMA>> {
    let mut d = [[L4([0.0; 4]); 3]; 3];
    for l in 0..4 {
        let p0 = x[t[l][0]];
        for c in 0..3 {
            let e = x[t[l][c + 1]] - p0;
            for a in 0..3 {
                d[a][c].0[l] = e[a];
            }
        }
    }
    d
}

/// `-V P Dm^-T` (column `j`: the force on node `j`, `j = 1..3`).
#[inline(always)]
fn h_cols<const FMA: bool>(p: &M3<L4<FMA>>, dm_inv: &M3<L4<FMA>>, minus_v: L4<FMA>) -> M3<L4<FMA>> {
    let mut h = [[L4([0.0; 4]); 3]; 3];
    for a in 0..3 {
        for j in 0..3 {
            h[a][j] = minus_v.mul(p[a][2].madd(dm_inv[j][2], p[a][1].madd(dm_inv[j][1], p[a][0].mul(dm_inv[j][0]))));
        }
    }
    h
}

/// `sum_ab m_ab^2` and `tr m`.
#[inline(always)]
fn norm2_trace<const FMA: bool>(m: &M3<L4<FMA>>) -> (L4<FMA>, L4<FMA>) {
    let mut s = L4([0.0; 4]);
    for a in 0..3 {
        for b in 0..3 {
            s = m[a][b].madd(m[a][b], s);
        }
    }
    (s, m[0][0].add(m[1][1]).add(m[2][2]))
}

/// Add the nodal forces of lane `l` (`[-(h1 + h2 + h3), h1, h2, h3]`) into `f`.
#[inline(always)]
fn scatter<const FMA: bool>(h: &M3<L4<FMA>>, l: usize, t: &[usize; 4], f: &mut [Vec3]) {
    let h1 = Vec3::new(h[0][0].0[l], h[1][0].0[l], h[2][0].0[l]);
    let h2 = Vec3::new(h[0][1].0[l], h[1][1].0[l], h[2][1].0[l]);
    let h3 = Vec3::new(h[0][2].0[l], h[1][2].0[l], h[2][2].0[l]);
    f[t[0]] -= h1 + h2 + h3;
    f[t[1]] += h1;
    f[t[2]] += h2;
    f[t[3]] += h3;
}

#[inline(always)]
fn run_lanes<const FMA: bool>(lp: &ElementLoop<'_>, x: &[Vec3], f_el: &mut [Vec3], f_visc: &mut [Vec3]) -> ElementSums {
    let n = lp.tets.len();
    let (lambda, mu) = lp.law.lame();
    let elastic = lp.law.without_viscosity();
    let mut sums = ElementSums::default();
    let zero = L4::<FMA>([0.0; 4]);
    let mut start = 0;
    while start < n {
        let m = (n - start).min(4);
        // Lanes past the last element repeat it; their results are not used.
        let mut t = [[0usize; 4]; 4];
        let mut dm_inv = [[zero; 3]; 3];
        let mut vol = zero;
        for l in 0..4 {
            let k = start + l.min(m - 1);
            t[l] = lp.tets[k];
            let r = &lp.rest[k];
            vol.0[l] = r.volume;
            for a in 0..3 {
                for b in 0..3 {
                    dm_inv[a][b].0[l] = r.dm_inv[(a, b)];
                }
            }
        }
        // F = Ds Dm^-1 (eq. 21), E, S (eq. 3-9), P = F S; psi = mu E:E + lambda/2 tr(E)^2.
        let f = mm(&ds::<FMA>(x, &t), &dm_inv);
        let g = green_strain_of(&f);
        let p = mm(&f, &elastic.stress(&g, None));
        let (ee, tr) = norm2_trace(&g);
        let w = vol.mul(L4::splat(mu).mul(ee).add(L4::splat(0.5 * lambda).mul(tr.mul(tr))));
        let det = det3(&f);
        let minus_v = zero.sub(vol);
        let hm = h_cols(&p, &dm_inv, minus_v);
        for l in 0..m {
            scatter(&hm, l, &t[l], f_el);
            sums.w += w.0[l];
            sums.f2 += w.0[l] * lp.stiffness[start + l];
            sums.inverted += (det.0[l] <= 0.0) as usize;
        }
        if let Some(((phi, psi), x_n, h)) = lp.viscous {
            // D = V/h (phi/2 tr(dE)^2 + psi dE:dE), S_v = (phi tr(dE) I + 2 psi dE) / h.
            let gn = green_strain_of(&mm(&ds::<FMA>(x_n, &t), &dm_inv));
            let mut de = g;
            for a in 0..3 {
                for b in 0..3 {
                    de[a][b] = g[a][b].sub(gn[a][b]);
                }
            }
            let (dd, trd) = norm2_trace(&de);
            let inv_h = 1.0 / h;
            let dis = vol.mul(L4::splat(0.5 * phi * inv_h).mul(trd.mul(trd)).add(L4::splat(psi * inv_h).mul(dd)));
            let two_psi = L4::<FMA>::splat(2.0 * psi * inv_h);
            let t_phi = L4::<FMA>::splat(phi * inv_h).mul(trd);
            let mut sv = de;
            for a in 0..3 {
                for b in 0..3 {
                    sv[a][b] = two_psi.mul(de[a][b]);
                }
                sv[a][a] = sv[a][a].add(t_phi);
            }
            let hv = h_cols(&mm(&f, &sv), &dm_inv, minus_v);
            for l in 0..m {
                scatter(&hv, l, &t[l], f_visc);
                sums.d += dis.0[l];
            }
        }
        start += m;
    }
    sums
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{tet4, viscous};
    use crate::material::{Damping, Elasticity, Material};

    /// Seven elements (one full chunk of four and a tail of three) sharing nodes, deformed.
    fn case() -> (Vec<[usize; 4]>, Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
        let rest: Vec<Vec3> = (0..10)
            .map(|i| Vec3::new((i % 3) as f64 * 0.01, ((i / 3) % 3) as f64 * 0.01 + 0.001 * i as f64, (i / 5) as f64 * 0.012 + 0.0007 * (i * i % 7) as f64))
            .collect();
        let mut tets = vec![[0, 1, 3, 5], [1, 2, 4, 6], [3, 4, 6, 7], [0, 2, 5, 8], [5, 6, 7, 9], [1, 3, 4, 8], [2, 6, 8, 9]];
        for t in &mut tets {
            if TetRest::new(&t.map(|i| rest[i])).volume < 0.0 {
                t.swap(2, 3);
            }
        }
        let a = crate::math::Mat3::new(1.05, 0.02, -0.03, 0.01, 0.97, 0.04, -0.02, 0.03, 1.02);
        let b = crate::math::Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        let xn = rest.iter().map(|p| a * p).collect();
        let x = rest.iter().enumerate().map(|(i, p)| b * p + Vec3::new(1e-4 * i as f64, 0.0, -2e-4)).collect();
        (tets, rest, xn, x)
    }

    #[test]
    fn the_lanes_give_the_element_by_element_sums_and_forces() {
        let (tets, rest, xn, x) = case();
        let m = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping { phi: 3.0, psi: 7.0 }).unwrap();
        let rests: Vec<TetRest> = tets.iter().map(|t| TetRest::new(&t.map(|i| rest[i]))).collect();
        assert!(rests.iter().all(|r| r.volume > 1e-9));
        let stiffness: Vec<f64> = (0..tets.len()).map(|k| 1.0 + k as f64).collect();
        let h = 1e-3;
        let n = x.len();
        let (mut fe, mut fv) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        let mut want = ElementSums::default();
        for (k, (t, r)) in tets.iter().zip(&rests).enumerate() {
            let (w, f, det) = tet4::elastic_energy_forces(&t.map(|i| x[i]), r, &m);
            let (d, v) = viscous::step_dissipation(&t.map(|i| x[i]), &t.map(|i| xn[i]), r, &m, h);
            want.w += w;
            want.d += d;
            want.f2 += w * stiffness[k];
            want.inverted += (det <= 0.0) as usize;
            for a in 0..4 {
                fe[t[a]] += f[a];
                fv[t[a]] += v[a];
            }
        }
        let scale = |f: &[Vec3]| f.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(scale(&fe) > 0.0 && scale(&fv) > 0.0 && want.w > 0.0 && want.d > 0.0);
        let d = m.damping();
        for viscous in [true, false] {
            for simd in [true, false] {
                let lp = ElementLoop {
                    tets: &tets,
                    rest: &rests,
                    stiffness: &stiffness,
                    law: Svk::of(&m),
                    viscous: viscous.then_some(((d.phi, d.psi), &xn[..], h)),
                };
                let (mut ge, mut gv) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
                let got = lp.run_copy(simd, &x, &mut ge, &mut gv);
                assert!((got.w - want.w).abs() <= 1e-13 * want.w && (got.f2 - want.f2).abs() <= 1e-13 * want.f2);
                assert_eq!(got.inverted, want.inverted);
                for i in 0..n {
                    assert!((ge[i] - fe[i]).norm() <= 1e-12 * scale(&fe), "elastic force, node {i} (simd {simd})");
                }
                if viscous {
                    assert!((got.d - want.d).abs() <= 1e-12 * want.d);
                    for i in 0..n {
                        assert!((gv[i] - fv[i]).norm() <= 1e-12 * scale(&fv), "viscous force, node {i} (simd {simd})");
                    }
                } else {
                    assert!(got.d == 0.0 && gv.iter().all(|v| *v == Vec3::zeros()));
                }
            }
        }
        // An inverted element is counted.
        let mut flipped = x.clone();
        flipped[9] = Vec3::new(0.0, 0.0, -0.05);
        let lp = ElementLoop { tets: &tets, rest: &rests, stiffness: &stiffness, law: Svk::of(&m), viscous: None };
        let want_inv = tets.iter().zip(&rests).filter(|(t, r)| tet4::elastic_energy_forces(&t.map(|i| flipped[i]), r, &m).2 <= 0.0).count();
        assert!(want_inv > 0);
        let (mut ge, mut gv) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        assert_eq!(lp.run(&flipped, &mut ge, &mut gv).inverted, want_inv);
    }
}
