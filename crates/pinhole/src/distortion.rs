//! OpenCV's 5-coefficient lens distortion (Brown–Conrady: radial k1, k2, k3, tangential p1, p2),
//! on normalised image coordinates `(x, y) = (X/Z, Y/Z)`:
//!
//! ```text
//! r² = x² + y²,  radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
//! x_d = x · radial + 2 p1 x y + p2 (r² + 2 x²)
//! y_d = y · radial + p1 (r² + 2 y²) + 2 p2 x y
//! ```
//!
//! Undistorting an image maps each output (undistorted) pixel through this model to the
//! recorded (distorted) image and samples there — what OpenCV's `undistort` does with the camera
//! matrix as the new one (`scene::image_io::undistort` does the sampling).

/// Distortion coefficients in OpenCV's order `(k1, k2, p1, p2, k3)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    /// Radial, r².
    pub k1: f64,
    /// Radial, r⁴.
    pub k2: f64,
    /// Tangential (y).
    pub p1: f64,
    /// Tangential (x).
    pub p2: f64,
    /// Radial, r⁶.
    pub k3: f64,
}

impl Distortion {
    /// From OpenCV's coefficient vector: 4 (`k1 k2 p1 p2`) or 5 (`… k3`) values; 8-coefficient
    /// rational models and others are refused (`None`), as are non-finite values.
    pub fn from_opencv(d: &[f64]) -> Option<Self> {
        if !d.iter().all(|v| v.is_finite()) {
            return None;
        }
        match *d {
            [k1, k2, p1, p2] => Some(Self {
                k1,
                k2,
                p1,
                p2,
                k3: 0.0,
            }),
            [k1, k2, p1, p2, k3] => Some(Self { k1, k2, p1, p2, k3 }),
            _ => None,
        }
    }

    /// True when every coefficient is zero (undistorting is the identity).
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }

    /// The distorted normalised coordinates of the undistorted `(x, y)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_matches_its_formula_and_refuses_other_lengths() {
        let d = Distortion::from_opencv(&[-0.2, 0.05, 0.001, -0.002, 0.01]).expect("5 values");
        let (x, y) = (0.3, -0.4);
        let r2: f64 = 0.25;
        let radial = 1.0 - 0.2 * r2 + 0.05 * r2 * r2 + 0.01 * r2 * r2 * r2;
        let xd = x * radial + 2.0 * 0.001 * x * y - 0.002 * (r2 + 2.0 * x * x);
        let yd = y * radial + 0.001 * (r2 + 2.0 * y * y) + 2.0 * -0.002 * x * y;
        let (ax, ay) = d.distort(x, y);
        assert!((ax - xd).abs() < 1e-15 && (ay - yd).abs() < 1e-15);
        assert_eq!(Distortion::default().distort(x, y), (x, y));
        assert!(Distortion::from_opencv(&[0.0; 8]).is_none());
        assert!(Distortion::from_opencv(&[f64::NAN, 0.0, 0.0, 0.0]).is_none());
        assert_eq!(
            Distortion::from_opencv(&[0.1, 0.0, 0.0, 0.0]).map(|d| d.k3),
            Some(0.0)
        );
    }
}
