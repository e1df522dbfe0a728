//! Small numerical tools used across the core: Gauss–Legendre quadrature (for tests and
//! cross-checks of closed forms), golden-section minimisation, a series-spring helper and a
//! 2-D rotation helper.
//!
//! Everything here is allocation-free after construction and deterministic.

use nalgebra::Vector2;

/// A 2-vector in metres, newtons or metres per second, depending on context (world frame unless
/// stated otherwise).
pub type Vec2 = Vector2<f64>;

/// Stiffness of two springs in series, `k1 k2 / (k1 + k2)` (N/m).
///
/// Used for the contact (k_e) in series with the force sensor (8.8e6 N/m, thesis §4.5.1).
pub fn series_stiffness(k1: f64, k2: f64) -> f64 {
    if k1 <= 0.0 || k2 <= 0.0 {
        return 0.0;
    }
    k1 * k2 / (k1 + k2)
}

/// Unit vector at `angle` (rad) from the world X axis.
pub fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

/// `v` rotated by +90° (counter-clockwise).
pub fn perp(v: Vec2) -> Vec2 {
    Vec2::new(-v.y, v.x)
}

/// `v` turned by `angle` (rad, counter-clockwise): a vector of a frame turned by `angle` in the
/// frame it was turned from.
pub fn turn(v: [f64; 2], angle: f64) -> [f64; 2] {
    let (s, c) = angle.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1]]
}

/// Planar cross product `a × b` (z component).
pub fn cross(a: Vec2, b: Vec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut x = a % two_pi;
    if x <= -std::f64::consts::PI {
        x += two_pi;
    } else if x > std::f64::consts::PI {
        x -= two_pi;
    }
    x
}

/// An `N`-point Gauss–Legendre rule on [−1, 1].
///
/// Nodes are the roots of the Legendre polynomial P_N, found by Newton iteration from the
/// Chebyshev guesses; weights are `2 / ((1 − x²) P_N'(x)²)`. Exact for polynomials of degree
/// ≤ 2N − 1.
#[derive(Debug, Clone)]
pub struct GaussLegendre<const N: usize> {
    nodes: [f64; N],
    weights: [f64; N],
}

impl<const N: usize> Default for GaussLegendre<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> GaussLegendre<N> {
    /// Computes the rule.
    pub fn new() -> Self {
        let mut nodes = [0.0; N];
        let mut weights = [0.0; N];
        let n = N as f64;
        for i in 0..N {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (p, d) = legendre(N, x);
                dp = d;
                let dx = p / d;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let (_, d) = legendre(N, x);
            if d.is_finite() {
                dp = d;
            }
            nodes[i] = x;
            weights[i] = 2.0 / ((1.0 - x * x) * dp * dp);
        }
        Self { nodes, weights }
    }

    /// ∫_a^b f(x) dx.
    pub fn integrate(&self, a: f64, b: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
        let half = 0.5 * (b - a);
        let mid = 0.5 * (b + a);
        let mut sum = 0.0;
        for i in 0..N {
            sum += self.weights[i] * f(mid + half * self.nodes[i]);
        }
        sum * half
    }

    /// ∫_a^b f(x) dx on `pieces` equal sub-intervals (composite rule).
    pub fn integrate_composite(
        &self,
        a: f64,
        b: f64,
        pieces: usize,
        mut f: impl FnMut(f64) -> f64,
    ) -> f64 {
        let pieces = pieces.max(1);
        let h = (b - a) / pieces as f64;
        (0..pieces)
            .map(|k| {
                let lo = a + h * k as f64;
                self.integrate(lo, lo + h, &mut f)
            })
            .sum()
    }
}

/// Legendre polynomial P_n(x) and its derivative by the three-term recurrence.
fn legendre(n: usize, x: f64) -> (f64, f64) {
    let mut p0 = 1.0;
    let mut p1 = x;
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let k = k as f64;
        let p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
    }
    let d = n as f64 * (x * p1 - p0) / (x * x - 1.0);
    (p1, d)
}

/// Minimises a unimodal `f` on [a, b] by golden-section search; returns (x, f(x)).
pub fn golden_section(
    mut a: f64,
    mut b: f64,
    iterations: usize,
    mut f: impl FnMut(f64) -> f64,
) -> (f64, f64) {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let mut fc = f(c);
    let mut fd = f(d);
    for _ in 0..iterations {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - r * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + r * (b - a);
            fd = f(d);
        }
    }
    if fc < fd { (c, fc) } else { (d, fd) }
}

/// Minimises `f` over [lo, hi] globally on a grid of `grid` points (log-spaced if `lo > 0`),
/// then refines the best bracket by golden section. Returns (x, f(x)).
pub fn grid_then_golden(
    lo: f64,
    hi: f64,
    grid: usize,
    refine: usize,
    mut f: impl FnMut(f64) -> f64,
) -> (f64, f64) {
    let grid = grid.max(3);
    let log = lo > 0.0;
    let at = |i: usize| -> f64 {
        let s = i as f64 / (grid - 1) as f64;
        if log {
            (lo.ln() + s * (hi.ln() - lo.ln())).exp()
        } else {
            lo + s * (hi - lo)
        }
    };
    let mut best_i = 0;
    let mut best_f = f64::INFINITY;
    for i in 0..grid {
        let v = f(at(i));
        if v < best_f {
            best_f = v;
            best_i = i;
        }
    }
    let a = at(best_i.saturating_sub(1));
    let b = at((best_i + 1).min(grid - 1));
    let (x, fx) = golden_section(a, b, refine, &mut f);
    if fx <= best_f {
        (x, fx)
    } else {
        (at(best_i), best_f)
    }
}

/// Pearson correlation of the pairs `(x, y)`; NaN with fewer than two pairs or a constant
/// coordinate.
pub fn correlation(pairs: &[[f64; 2]]) -> f64 {
    let n = pairs.len() as f64;
    if pairs.len() < 2 {
        return f64::NAN;
    }
    let mx = pairs.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = pairs.iter().map(|p| p[1]).sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for p in pairs {
        let (dx, dy) = (p[0] - mx, p[1] - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx == 0.0 || syy == 0.0 {
        return f64::NAN;
    }
    sxy / (sxx * syy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `turn` is nalgebra's rotation, and turning back undoes it.
    #[test]
    fn turn_is_the_rotation() {
        for (v, a) in [([1.0, 0.0], 0.3), ([0.2, -1.5], -2.0), ([3.0, 4.0], 1e-3)] {
            let r = nalgebra::Rotation2::new(a) * Vec2::new(v[0], v[1]);
            let t = turn(v, a);
            assert!(
                (t[0] - r.x).abs() < 1e-14 && (t[1] - r.y).abs() < 1e-14,
                "{v:?} {a}"
            );
            let back = turn(t, -a);
            assert!((back[0] - v[0]).abs() < 1e-14 && (back[1] - v[1]).abs() < 1e-14);
        }
    }

    /// Gauss–Legendre with N points integrates x^(2N−1) exactly.
    #[test]
    fn gauss_legendre_is_exact_for_degree_2n_minus_1() {
        let gl = GaussLegendre::<8>::new();
        let got = gl.integrate(0.0, 2.0, |x| x.powi(15));
        let expected = 2f64.powi(16) / 16.0;
        assert!(
            (got - expected).abs() < 1e-9 * expected,
            "{got} vs {expected}"
        );
        let w: f64 = gl.weights.iter().sum();
        assert!((w - 2.0).abs() < 1e-14);
    }

    #[test]
    fn golden_section_finds_parabola_minimum() {
        let (x, fx) = golden_section(-3.0, 5.0, 80, |x| (x - 1.25).powi(2) + 0.5);
        assert!((x - 1.25).abs() < 1e-8, "{x}");
        assert!((fx - 0.5).abs() < 1e-12);
    }

    #[test]
    fn grid_then_golden_finds_the_global_of_two_minima() {
        // Local minimum at 0.1 (value 1), global at 3 (value 0).
        let f = |x: f64| ((x - 0.1).powi(2) + 1.0).min((x - 3.0).powi(2));
        let (x, _) = grid_then_golden(0.01, 10.0, 40, 60, f);
        assert!((x - 3.0).abs() < 1e-6, "{x}");
    }

    #[test]
    fn series_stiffness_of_thesis_contact() {
        let k = series_stiffness(10e3, 8.8e6);
        assert!((k - 1.0 / (1.0 / 10e3 + 1.0 / 8.8e6)).abs() < 1e-9);
        assert_eq!(series_stiffness(0.0, 1.0), 0.0);
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for k in -20..20 {
            let a = k as f64 * 0.7;
            let w = wrap_angle(a);
            assert!(w > -std::f64::consts::PI - 1e-12 && w <= std::f64::consts::PI + 1e-12);
            assert!(((a - w) / std::f64::consts::TAU).fract().abs() < 1e-9);
        }
    }

    /// Hand-computed: x = 1, 2, 3, y = 1, 3, 2 has Sxy = 1, Sxx = Syy = 2, r = 0.5.
    #[test]
    fn correlation_matches_hand_computation() {
        assert!((correlation(&[[1.0, 1.0], [2.0, 3.0], [3.0, 2.0]]) - 0.5).abs() < 1e-15);
        assert!((correlation(&[[0.0, 1.0], [1.0, -1.0]]) + 1.0).abs() < 1e-15);
        assert!(correlation(&[[1.0, 1.0]]).is_nan());
        assert!(correlation(&[[1.0, 1.0], [1.0, 2.0]]).is_nan());
    }
}
