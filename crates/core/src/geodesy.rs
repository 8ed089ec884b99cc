//! WGS84 geodesy: geodetic ↔ ECEF ↔ a local east-north-up frame about a datum. Exact (no
//! flat-earth approximation), so round trips at 10 km stay well under a millimetre.

use nalgebra::{Matrix3, Vector3};

/// WGS84 semi-major axis, m.
pub const A: f64 = 6_378_137.0;
/// WGS84 flattening.
pub const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
pub const E2: f64 = F * (2.0 - F);
/// Semi-minor axis, m.
pub const B: f64 = A * (1.0 - F);
/// Heights a vehicle on the ground can have, m above the ellipsoid: below the Dead Sea's
/// shore less the geoid's lowest, above any road.
pub const PLAUSIBLE_HEIGHT_M: std::ops::RangeInclusive<f64> = -500.0..=10_000.0;

/// A WGS84 position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub h_m: f64,
}

impl Geodetic {
    /// Earth-centred, earth-fixed coordinates, m.
    pub fn to_ecef(&self) -> Vector3<f64> {
        let (lat, lon) = (self.lat_deg.to_radians(), self.lon_deg.to_radians());
        let (sl, cl) = lat.sin_cos();
        let n = A / (1.0 - E2 * sl * sl).sqrt();
        Vector3::new(
            (n + self.h_m) * cl * lon.cos(),
            (n + self.h_m) * cl * lon.sin(),
            (n * (1.0 - E2) + self.h_m) * sl,
        )
    }

    /// The geodetic position of ECEF coordinates: Bowring's start, then Newton iterations on
    /// the latitude until it stops changing (converges in two or three).
    pub fn from_ecef(p: &Vector3<f64>) -> Self {
        let lon = p.y.atan2(p.x);
        let r = (p.x * p.x + p.y * p.y).sqrt();
        if r < 1e-9 {
            // On the axis: a pole (or the centre).
            let lat = if p.z >= 0.0 { 90.0 } else { -90.0 };
            return Self {
                lat_deg: lat,
                lon_deg: 0.0,
                h_m: p.z.abs() - B,
            };
        }
        let ep2 = (A * A - B * B) / (B * B);
        let theta = (p.z * A).atan2(r * B);
        let (st, ct) = theta.sin_cos();
        let mut lat = (p.z + ep2 * B * st.powi(3)).atan2(r - E2 * A * ct.powi(3));
        for _ in 0..5 {
            let sl = lat.sin();
            let n = A / (1.0 - E2 * sl * sl).sqrt();
            let next = (p.z + E2 * n * sl).atan2(r);
            let done = (next - lat).abs() < 1e-15;
            lat = next;
            if done {
                break;
            }
        }
        let (sl, cl) = lat.sin_cos();
        let n = A / (1.0 - E2 * sl * sl).sqrt();
        // Height from whichever form is well conditioned at this latitude.
        let h = if cl.abs() > 1e-3 {
            r / cl - n
        } else {
            p.z / sl - n * (1.0 - E2)
        };
        Self {
            lat_deg: lat.to_degrees(),
            lon_deg: lon.to_degrees(),
            h_m: h,
        }
    }
}

/// A local east-north-up frame anchored at a datum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Enu {
    datum: Geodetic,
    origin: Vector3<f64>,
    /// ECEF → ENU rotation.
    rotation: Matrix3<f64>,
}

impl Enu {
    /// The frame whose origin is `datum`.
    pub fn new(datum: Geodetic) -> Self {
        let (lat, lon) = (datum.lat_deg.to_radians(), datum.lon_deg.to_radians());
        let (sl, cl) = lat.sin_cos();
        let (so, co) = lon.sin_cos();
        let rotation = Matrix3::new(
            -so,
            co,
            0.0, //
            -sl * co,
            -sl * so,
            cl, //
            cl * co,
            cl * so,
            sl,
        );
        Self {
            datum,
            origin: datum.to_ecef(),
            rotation,
        }
    }

    /// The datum.
    pub fn datum(&self) -> Geodetic {
        self.datum
    }

    /// East, north, up of a position, m.
    pub fn to_enu(&self, p: &Geodetic) -> Vector3<f64> {
        self.rotation * (p.to_ecef() - self.origin)
    }

    /// The position at east, north, up (m).
    pub fn to_geodetic(&self, enu: &Vector3<f64>) -> Geodetic {
        Geodetic::from_ecef(&(self.origin + self.rotation.transpose() * enu))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g(lat_deg: f64, lon_deg: f64, h_m: f64) -> Geodetic {
        Geodetic {
            lat_deg,
            lon_deg,
            h_m,
        }
    }

    #[test]
    fn known_ecef_points() {
        let p = g(0.0, 0.0, 0.0).to_ecef();
        assert!((p - Vector3::new(A, 0.0, 0.0)).norm() < 1e-9);
        let p = g(90.0, 0.0, 0.0).to_ecef();
        assert!((p - Vector3::new(0.0, 0.0, B)).norm() < 1e-6);
        let p = g(0.0, 90.0, 100.0).to_ecef();
        assert!((p - Vector3::new(0.0, A + 100.0, 0.0)).norm() < 1e-6);
        // A published reference: 45° N, 45° E, 0 m.
        let p = g(45.0, 45.0, 0.0).to_ecef();
        let expected = Vector3::new(3_194_419.145, 3_194_419.145, 4_487_348.409);
        assert!((p - expected).norm() < 1e-3, "{p}");
        let back = Geodetic::from_ecef(&Vector3::new(0.0, 0.0, -B - 10.0));
        assert_eq!(back.lat_deg, -90.0);
        assert!((back.h_m - 10.0).abs() < 1e-6);
    }

    #[test]
    fn ecef_round_trips_everywhere() {
        let mut worst: f64 = 0.0;
        for lat in (-89..=89).step_by(7) {
            for lon in (-180..=180).step_by(13) {
                for h in [-100.0, 0.0, 1234.5, 20_000.0] {
                    let p = g(
                        f64::from(lat) + 0.123_456_789,
                        f64::from(lon) + 0.987_654_321,
                        h,
                    );
                    let back = Geodetic::from_ecef(&p.to_ecef());
                    worst = worst.max((back.to_ecef() - p.to_ecef()).norm());
                    assert!((back.lat_deg - p.lat_deg).abs() < 1e-11, "{p:?} {back:?}");
                    assert!((back.h_m - p.h_m).abs() < 1e-6, "{p:?} {back:?}");
                }
            }
        }
        assert!(worst < 1e-6, "worst round trip {worst} m");
    }

    #[test]
    fn enu_is_exact_at_ten_kilometres() {
        let datum = g(23.149_652_496_5, 113.019_636_645_666_7, 12.3);
        let frame = Enu::new(datum);
        assert!(frame.to_enu(&datum).norm() < 1e-9);
        for (e, n, u) in [
            (10_000.0, 0.0, 0.0),
            (0.0, 10_000.0, 0.0),
            (-7071.0, 7071.0, 5.0),
            (3.0, -4.0, 0.0),
        ] {
            let enu = Vector3::new(e, n, u);
            let p = frame.to_geodetic(&enu);
            let back = frame.to_enu(&p);
            assert!(
                (back - enu).norm() < 1e-4,
                "{enu} → {back}: more than 0.1 mm"
            );
        }
        // North is north: 1 km north raises the latitude by about 1000/111 km degrees.
        let p = frame.to_geodetic(&Vector3::new(0.0, 1000.0, 0.0));
        assert!(
            (p.lat_deg - datum.lat_deg - 0.009_035).abs() < 1e-5,
            "{p:?}"
        );
        assert!((p.lon_deg - datum.lon_deg).abs() < 1e-9);
        // The surface drops away: 10 km east at constant height is below the tangent plane.
        let ten_east = g(datum.lat_deg, datum.lon_deg + 0.0977, datum.h_m);
        let enu = frame.to_enu(&ten_east);
        assert!(enu.z < -7.0 && enu.z > -9.0, "{enu}");
    }
}
