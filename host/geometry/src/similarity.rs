//! The least-squares similarity (rotation, uniform scale, shift) between two sets of matched points: how a camera's
//! roll shows in its image, in the simulator's truth and in the estimator's motion fit alike.

use crate::Point2;

/// `to = to_centroid + z (from - from_centroid)` with z = scale e^(i rotation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    /// From +x towards +y, radians.
    pub rotation: f64,
    pub scale: f64,
    pub from_centroid: Point2,
    pub to_centroid: Point2,
}

impl Similarity {
    pub const IDENTITY: Self = Self {
        rotation: 0.0,
        scale: 1.0,
        from_centroid: [0.0, 0.0],
        to_centroid: [0.0, 0.0],
    };

    /// The similarity that best maps each pair's first point onto its second (least squares); `None` without pairs.
    /// Points that do not spread (all in one place) give scale 0.
    pub fn fit<'a>(pairs: impl Iterator<Item = &'a (Point2, Point2)> + Clone) -> Option<Self> {
        let n = pairs.clone().count();
        if n == 0 {
            return None;
        }
        let n = n as f64;
        let mean = |side: fn(&(Point2, Point2)) -> Point2| {
            let sum = pairs
                .clone()
                .map(side)
                .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
            [sum[0] / n, sum[1] / n]
        };
        let (from_centroid, to_centroid) = (mean(|p| p.0), mean(|p| p.1));
        // z = sum conj(a) b / sum |a|^2 over the centred pairs, in complex numbers.
        let (mut re, mut im, mut norm) = (0.0f64, 0.0f64, 0.0f64);
        for (a, b) in pairs {
            let (x, y) = (a[0] - from_centroid[0], a[1] - from_centroid[1]);
            let (u, v) = (b[0] - to_centroid[0], b[1] - to_centroid[1]);
            re += x * u + y * v;
            im += x * v - y * u;
            norm += x * x + y * y;
        }
        Some(Self {
            rotation: im.atan2(re),
            scale: re.hypot(im) / norm.max(f64::MIN_POSITIVE),
            from_centroid,
            to_centroid,
        })
    }

    /// Row-major 3x3 matrix of the map (homogeneous coordinates).
    pub fn matrix(&self) -> [f64; 9] {
        let (s, c) = self.rotation.sin_cos();
        let (a, b) = (self.scale * c, self.scale * s);
        let [fx, fy] = self.from_centroid;
        let [tx, ty] = self.to_centroid;
        [
            a,
            -b,
            tx - (a * fx - b * fy),
            b,
            a,
            ty - (b * fx + a * fy),
            0.0,
            0.0,
            1.0,
        ]
    }

    pub fn apply(&self, p: Point2) -> Point2 {
        let m = self.matrix();
        [m[0] * p[0] + m[1] * p[1] + m[2], m[3] * p[0] + m[4] * p[1] + m[5]]
    }

    /// How far the centroid moved.
    pub fn shift(&self) -> Point2 {
        [
            self.to_centroid[0] - self.from_centroid[0],
            self.to_centroid[1] - self.from_centroid[1],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_motion_about_any_centre() {
        let (angle, scale, shift, about) = (3f64.to_radians(), 1.01, [4.0, -2.5], [160.0, 117.5]);
        let pairs: Vec<(Point2, Point2)> = (0..20)
            .map(|i| {
                let a = [f64::from(i % 5) * 30.0 + 100.0, f64::from(i / 5) * 25.0 + 80.0];
                let (dx, dy) = (a[0] - about[0], a[1] - about[1]);
                let b = [
                    about[0] + shift[0] + scale * (angle.cos() * dx - angle.sin() * dy),
                    about[1] + shift[1] + scale * (angle.sin() * dx + angle.cos() * dy),
                ];
                (a, b)
            })
            .collect();
        let fit = Similarity::fit(pairs.iter()).unwrap();
        assert!(
            (fit.rotation - angle).abs() < 1e-12 && (fit.scale - scale).abs() < 1e-12,
            "{fit:?}"
        );
        for (a, b) in &pairs {
            let q = fit.apply(*a);
            assert!((q[0] - b[0]).abs() < 1e-9 && (q[1] - b[1]).abs() < 1e-9);
        }
        assert_eq!(Similarity::fit([].iter()), None);
        let still = [([1.0, 2.0], [3.0, 4.0]); 3];
        assert_eq!(Similarity::fit(still.iter()).unwrap().scale, 0.0);
    }
}
