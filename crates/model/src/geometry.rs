//! Frames, Earth rate and two-axis table kinematics (see `docs/physics.md`).
//!
//! Local frame: North-East-Down. Body frame: x = the gyro's sensitive axis.
//! Orientation: aerospace Z-Y-X Euler angles, `R_nb = Rz(yaw) Ry(pitch) Rx(roll)`.

use nalgebra::{Rotation3, Unit, Vector3};
use serde::{Deserialize, Serialize};

use crate::config::{Checker, ConfigError};

/// Earth rotation rate, rad/s.
pub const EARTH_RATE_RAD_S: f64 = 7.292_115e-5;
/// Earth rotation rate, deg/h (= arcsec/s).
pub const EARTH_RATE_DPH: f64 = EARTH_RATE_RAD_S * 180.0 / std::f64::consts::PI * 3600.0;
/// deg/s to deg/h.
pub const DPS_TO_DPH: f64 = 3600.0;

/// Where the bench stands.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// Geodetic latitude, deg (north positive).
    pub latitude_deg: f64,
    /// Longitude, deg (east positive).
    pub longitude_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Earth magnetic field in NED, microtesla.
    pub magnetic_field_ned_ut: [f64; 3],
}

impl Site {
    /// Check the values, reporting bad ones under `prefix` (e.g. `site`).
    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<(), ConfigError> {
        c.within(
            self.latitude_deg,
            -90.0,
            90.0,
            &format!("{prefix}.latitude_deg"),
        )?;
        c.within(
            self.longitude_deg,
            -180.0,
            360.0,
            &format!("{prefix}.longitude_deg"),
        )?;
        c.within(
            self.height_m,
            -500.0,
            10_000.0,
            &format!("{prefix}.height_m"),
        )?;
        for v in self.magnetic_field_ned_ut {
            c.within(v, -100.0, 100.0, &format!("{prefix}.magnetic_field_ned_ut"))?;
        }
        Ok(())
    }

    /// Earth-rate vector in NED, deg/h: `W (cos phi, 0, -sin phi)`.
    pub fn earth_rate_ned_dph(&self) -> Vector3<f64> {
        let phi = self.latitude_deg.to_radians();
        Vector3::new(phi.cos(), 0.0, -phi.sin()) * EARTH_RATE_DPH
    }

    /// The direction the Earth rate turns in as the latitude grows, a
    /// unit vector in NED across it: `(-sin phi, 0, -cos phi)`. A
    /// latitude stated `x` rad too high adds `-x W` of it to the Earth
    /// rate the units sense against the one the bench subtracts.
    pub fn earth_rate_turned_ned(&self) -> Vector3<f64> {
        let phi = self.latitude_deg.to_radians();
        Vector3::new(-phi.sin(), 0.0, -phi.cos())
    }

    /// Magnetic field in NED, microtesla.
    pub fn magnetic_ned_ut(&self) -> Vector3<f64> {
        Vector3::from(self.magnetic_field_ned_ut)
    }
}

/// Gravity direction in NED, in g.
pub fn gravity_ned_g() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, 1.0)
}

/// Orientation of the gyro body in NED, degrees.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Orientation {
    /// Azimuth of the sensitive axis (yaw), deg.
    pub azimuth_deg: f64,
    /// Elevation of the sensitive axis above the horizon (pitch), deg.
    pub elevation_deg: f64,
    /// Rotation about the sensitive axis (roll), deg.
    pub roll_deg: f64,
}

impl Orientation {
    /// From yaw, pitch, roll in degrees.
    pub fn new(azimuth_deg: f64, elevation_deg: f64, roll_deg: f64) -> Self {
        Self {
            azimuth_deg,
            elevation_deg,
            roll_deg,
        }
    }

    /// Body-to-NED rotation `Rz(yaw) Ry(pitch) Rx(roll)`.
    pub fn rotation(&self) -> Rotation3<f64> {
        Rotation3::from_euler_angles(
            self.roll_deg.to_radians(),
            self.elevation_deg.to_radians(),
            self.azimuth_deg.to_radians(),
        )
    }

    /// Euler angles of a body-to-NED rotation (azimuth wrapped to [0, 360)).
    pub fn from_rotation(r: &Rotation3<f64>) -> Self {
        let (roll, pitch, yaw) = r.euler_angles();
        Self {
            azimuth_deg: yaw.to_degrees().rem_euclid(360.0),
            elevation_deg: pitch.to_degrees(),
            roll_deg: roll.to_degrees(),
        }
    }

    /// Sensitive axis in NED: `(cos p cos y, cos p sin y, -sin p)`.
    pub fn sensitive_axis_ned(&self) -> Vector3<f64> {
        self.rotation() * Vector3::x()
    }

    /// Earth rate seen on the sensitive axis, deg/h:
    /// `W (sin e sin phi + cos e cos psi cos phi)`.
    pub fn earth_rate_dph(&self, site: &Site) -> f64 {
        site.earth_rate_ned_dph().dot(&self.sensitive_axis_ned())
    }
}

/// Angle between two rotations, degrees.
pub fn rotation_distance_deg(a: &Rotation3<f64>, b: &Rotation3<f64>) -> f64 {
    (a.inverse() * b).angle().to_degrees()
}

/// Geometry of a two-axis table: which way its axes point when both read
/// zero, and how the gyro sits on the inner axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableGeometry {
    /// Outer axis direction in NED (a positive outer angle turns right-handed
    /// about it).
    pub outer_axis_ned: [f64; 3],
    /// Inner axis direction in NED with the outer axis at zero.
    pub inner_axis_ned: [f64; 3],
    /// Body orientation in NED with both table angles at zero.
    pub mount: Orientation,
}

/// Table axis angles, deg.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableAngles {
    /// Outer axis angle, deg.
    pub outer_deg: f64,
    /// Inner axis angle, deg.
    pub inner_deg: f64,
}

/// An orientation the table cannot reach.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the table cannot reach azimuth {:.2} deg, elevation {:.2} deg, roll {:.2} deg: \
     the nearest pose is {error_deg:.3} deg away; choose an orientation the table geometry allows \
     or give table angles",
    target.azimuth_deg, target.elevation_deg, target.roll_deg
)]
pub struct Unreachable {
    /// The orientation asked for.
    pub target: Orientation,
    /// Angle between the target and the nearest reachable pose, deg.
    pub error_deg: f64,
}

/// Tolerance for calling an orientation reachable, deg.
pub const REACH_TOLERANCE_DEG: f64 = 0.01;

impl TableGeometry {
    /// Check the axes are directions, reporting under `prefix`.
    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<(), ConfigError> {
        for (v, name) in [
            (self.outer_axis_ned, "outer_axis_ned"),
            (self.inner_axis_ned, "inner_axis_ned"),
        ] {
            c.direction(&v, &format!("{prefix}.{name}"))?;
        }
        let a = Vector3::from(self.outer_axis_ned).normalize();
        let b = Vector3::from(self.inner_axis_ned).normalize();
        c.ensure(
            a.cross(&b).norm() > 1e-3,
            &format!("{prefix}.inner_axis_ned"),
            "must not be parallel to the outer axis (a two-axis table needs two directions)",
        )?;
        let m = &self.mount;
        for (v, name) in [
            (m.azimuth_deg, "azimuth_deg"),
            (m.elevation_deg, "elevation_deg"),
            (m.roll_deg, "roll_deg"),
        ] {
            c.finite(v, &format!("{prefix}.mount.{name}"))?;
        }
        Ok(())
    }

    /// The geometry of `docs/physics.md`: outer axis horizontal on the
    /// north-south line (its positive sense south),
    /// inner axis perpendicular to it, sensitive axis along the inner axis.
    /// Outer 0 deg: axis horizontal (east); outer 90 deg: axis up;
    /// outer 35 deg: axis 55 deg from vertical.
    ///
    /// A positive outer angle raises the east end, i.e. it turns
    /// right-handed about south (`outer_axis_ned = [-1, 0, 0]`).
    pub fn study() -> Self {
        Self {
            outer_axis_ned: [-1.0, 0.0, 0.0],
            inner_axis_ned: [0.0, 1.0, 0.0],
            mount: Orientation::new(90.0, 0.0, 0.0),
        }
    }

    /// The study's table turned a quarter turn in azimuth, as a lab near
    /// the equator sets it up: outer axis horizontal on the east-west line
    /// (its positive sense east), inner axis north, sensitive axis along
    /// the inner axis. Outer 0 deg: axis horizontal north; outer 90 deg:
    /// axis up; outer 180 deg: axis horizontal south; outer 35 deg: the
    /// axis 55 deg from vertical, tilted toward north.
    ///
    /// Near the equator an up/down reversal sees almost no Earth rate
    /// (`W sin(latitude)`); north/south sees nearly all of it
    /// (`W cos(latitude)`), so the thermal cycle runs with the axis north
    /// (`procedures/thermal_cycle_north.toml`).
    pub fn north() -> Self {
        Self {
            outer_axis_ned: [0.0, 1.0, 0.0],
            inner_axis_ned: [1.0, 0.0, 0.0],
            mount: Orientation::new(0.0, 0.0, 0.0),
        }
    }

    fn outer_axis(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(Vector3::from(self.outer_axis_ned))
    }

    fn inner_axis(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(Vector3::from(self.inner_axis_ned))
    }

    /// Body-to-NED rotation at given table angles:
    /// `R_o(outer) R_i(inner) R_mount`.
    pub fn rotation(&self, a: TableAngles) -> Rotation3<f64> {
        let ro = Rotation3::from_axis_angle(&self.outer_axis(), a.outer_deg.to_radians());
        let ri = Rotation3::from_axis_angle(&self.inner_axis(), a.inner_deg.to_radians());
        ro * ri * self.mount.rotation()
    }

    /// Body orientation at given table angles.
    pub fn orientation(&self, a: TableAngles) -> Orientation {
        Orientation::from_rotation(&self.rotation(a))
    }

    /// Body angular velocity in NED, deg/s, for table angles and rates (deg/s).
    pub fn angular_velocity_ned_dps(&self, a: TableAngles, rates: TableAngles) -> Vector3<f64> {
        let ro = Rotation3::from_axis_angle(&self.outer_axis(), a.outer_deg.to_radians());
        self.outer_axis().into_inner() * rates.outer_deg
            + ro * self.inner_axis().into_inner() * rates.inner_deg
    }

    /// The table's angular velocity in the body frame, deg/h (what a
    /// misaligned sensitive axis picks a share of while the table turns).
    pub fn table_rate_body_dph(&self, a: TableAngles, rates: TableAngles) -> Vector3<f64> {
        self.rotation(a).inverse() * self.angular_velocity_ned_dps(a, rates) * DPS_TO_DPH
    }

    /// Rate the nominal sensitive axis sees from Earth rotation and table
    /// motion, deg/h (what a perfectly aligned gyro would read).
    pub fn kinematic_rate_dph(&self, site: &Site, a: TableAngles, rates: TableAngles) -> f64 {
        let axis = self.rotation(a) * Vector3::x();
        axis.dot(
            &(site.earth_rate_ned_dph() + self.angular_velocity_ned_dps(a, rates) * DPS_TO_DPH),
        )
    }

    /// Mean of [`kinematic_rate_dph`](Self::kinematic_rate_dph) over an
    /// interval of `dt_s` in which the table went from `from` to `to`
    /// (each a pose: angles, rates), each axis's rate changing linearly
    /// between them. A gyro's interval mean reads this, not the rate at the
    /// interval's end: turning at 5 deg/s about an axis across the
    /// sensitive one, the Earth rate on the axis turns with it, and its
    /// value at the end of a 1 s interval is half a second ahead of the
    /// mean (0.65 deg/h at the equator with the axis sweeping north and
    /// down). Simpson's rule on eight panels: within 1e-6 of the exact
    /// mean for a turn of 5 deg per interval. A table at rest at both ends
    /// gives the value at the end.
    pub fn mean_kinematic_rate_dph(
        &self,
        site: &Site,
        from: (TableAngles, TableAngles),
        to: (TableAngles, TableAngles),
        dt_s: f64,
    ) -> f64 {
        let at = |pose: (TableAngles, TableAngles)| self.kinematic_rate_dph(site, pose.0, pose.1);
        let still = |r: TableAngles| r.outer_deg == 0.0 && r.inner_deg == 0.0;
        if dt_s.is_nan() || dt_s <= 0.0 || (still(from.1) && still(to.1)) {
            return at(to);
        }
        // Each axis: the angle the rates say it turned, corrected to the
        // end angle read (whole turns are the rates' to say); the rate is
        // the table's own reading, between the two ends (an angle read
        // over a link carries the read's timing: on a device bench a few
        // milliseconds of it would put tens of ppm into a rate run's
        // reference, where the table's rate reading does not).
        let axis = |a0: f64, a1: f64, r0: f64, r1: f64| {
            let expected = 0.5 * (r0 + r1) * dt_s;
            let read = a1 - a0;
            let turned = read + 360.0 * ((expected - read) / 360.0).round();
            let correction = turned - expected;
            move |s: f64| {
                let angle = a0 + dt_s * (r0 * s + 0.5 * (r1 - r0) * s * s) + correction * s;
                (angle, r0 + (r1 - r0) * s)
            }
        };
        let (start, end) = (from, to);
        let outer = axis(
            start.0.outer_deg,
            end.0.outer_deg,
            start.1.outer_deg,
            end.1.outer_deg,
        );
        let inner = axis(
            start.0.inner_deg,
            end.0.inner_deg,
            start.1.inner_deg,
            end.1.inner_deg,
        );
        const PANELS: usize = 8;
        let mut sum = 0.0;
        for k in 0..=PANELS {
            let s = k as f64 / PANELS as f64;
            let ((ao, ro), (ai, ri)) = (outer(s), inner(s));
            let w = if k == 0 || k == PANELS {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            sum += w * at((
                TableAngles {
                    outer_deg: ao,
                    inner_deg: ai,
                },
                TableAngles {
                    outer_deg: ro,
                    inner_deg: ri,
                },
            ));
        }
        sum / (3.0 * PANELS as f64)
    }

    /// Table angles that put the body in `target`, or why they do not exist.
    ///
    /// The inner axis is fixed in the inner gimbal, so the body-frame inner
    /// axis must land on `R_target R_mount^T a_i`; one rotation about the
    /// outer axis does that, then the inner angle takes up the rest.
    pub fn angles_for(&self, target: Orientation) -> Result<TableAngles, Unreachable> {
        let r_target = target.rotation();
        let a_o = self.outer_axis();
        let a_i = self.inner_axis().into_inner();
        let v = r_target * self.mount.rotation().inverse() * a_i;
        let outer = angle_about(&a_o, &a_i, &v);
        let ro = Rotation3::from_axis_angle(&a_o, outer);
        let ri_needed = ro.inverse() * r_target * self.mount.rotation().inverse();
        let inner = signed_angle_of(&ri_needed, &self.inner_axis());
        let angles = TableAngles {
            outer_deg: wrap_deg(outer.to_degrees()),
            inner_deg: wrap_deg(inner.to_degrees()),
        };
        let error_deg = rotation_distance_deg(&self.rotation(angles), &r_target);
        if error_deg <= REACH_TOLERANCE_DEG {
            Ok(angles)
        } else {
            Err(Unreachable { target, error_deg })
        }
    }
}

/// Rotation angle about `axis` that brings `from` closest to `to`.
fn angle_about(axis: &Unit<Vector3<f64>>, from: &Vector3<f64>, to: &Vector3<f64>) -> f64 {
    let k = axis.into_inner();
    let f = from - k * k.dot(from);
    let t = to - k * k.dot(to);
    if f.norm() < 1e-12 || t.norm() < 1e-12 {
        return 0.0;
    }
    k.dot(&f.cross(&t)).atan2(f.dot(&t))
}

/// Signed rotation angle of `r` about `axis` (its component about that axis).
fn signed_angle_of(r: &Rotation3<f64>, axis: &Unit<Vector3<f64>>) -> f64 {
    let k = axis.into_inner();
    // Any vector perpendicular to the axis, then see where r takes it.
    let helper = if k.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let p = (helper - k * k.dot(&helper)).normalize();
    angle_about(axis, &p, &(r * p))
}

/// Wrap an angle to (-180, 180], deg; values within a hair of 360 become 0.
pub fn wrap_deg(a: f64) -> f64 {
    let w = (a + 180.0).rem_euclid(360.0) - 180.0;
    if (w + 180.0).abs() < 1e-9 {
        180.0
    } else if w.abs() < 1e-9 {
        0.0
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kyiv() -> Site {
        Site {
            latitude_deg: 50.45,
            longitude_deg: 30.52,
            height_m: 180.0,
            magnetic_field_ned_ut: [19.5, 2.7, 46.5],
        }
    }

    fn closed_form(site: &Site, o: &Orientation) -> f64 {
        let (e, psi, phi) = (
            o.elevation_deg.to_radians(),
            o.azimuth_deg.to_radians(),
            site.latitude_deg.to_radians(),
        );
        EARTH_RATE_DPH * (e.sin() * phi.sin() + e.cos() * psi.cos() * phi.cos())
    }

    #[test]
    fn earth_rate_constant_matches_physics_notes() {
        assert!((EARTH_RATE_DPH - 15.0411).abs() < 1e-4);
    }

    #[test]
    fn the_earth_rate_turns_across_itself_as_the_latitude_grows() {
        let site = kyiv();
        let turned = site.earth_rate_turned_ned();
        assert!((turned.norm() - 1.0).abs() < 1e-12);
        assert!(turned.dot(&site.earth_rate_ned_dph()).abs() < 1e-12);
        // One hundredth of a degree further north: the Earth rate moves
        // along it by W times the angle, to first order.
        let mut north = site;
        north.latitude_deg += 0.01;
        let moved = north.earth_rate_ned_dph() - site.earth_rate_ned_dph();
        let want = turned * EARTH_RATE_DPH * 0.01_f64.to_radians();
        assert!((moved - want).norm() < 1e-6, "{moved:?} vs {want:?}");
    }

    #[test]
    fn study_geometry_reaches_the_nine_positions() {
        let g = TableGeometry::study();
        let site = kyiv();
        let phi = site.latitude_deg.to_radians();
        for inner in [0.0, 90.0, 180.0, 270.0] {
            let up = g.orientation(TableAngles {
                outer_deg: 90.0,
                inner_deg: inner,
            });
            assert!((up.elevation_deg - 90.0).abs() < 1e-6, "{up:?}");
            let w = up.earth_rate_dph(&site);
            assert!((w - EARTH_RATE_DPH * phi.sin()).abs() < 1e-9);

            let horiz = g.orientation(TableAngles {
                outer_deg: 0.0,
                inner_deg: inner,
            });
            assert!(horiz.elevation_deg.abs() < 1e-9);
            assert!((horiz.azimuth_deg - 90.0).abs() < 1e-9, "{horiz:?}");
            assert!(
                horiz.earth_rate_dph(&site).abs() < 1e-9,
                "east axis sees no Earth rate"
            );
        }
        let tilt = g.orientation(TableAngles {
            outer_deg: 35.0,
            inner_deg: 0.0,
        });
        assert!((tilt.elevation_deg - 35.0).abs() < 1e-9);
        let w = tilt.earth_rate_dph(&site);
        assert!((w - closed_form(&site, &tilt)).abs() < 1e-9);
    }

    #[test]
    fn the_north_table_puts_the_axis_north_up_and_south_and_tilts_it_toward_north() {
        let g = TableGeometry::north();
        let site = Site {
            latitude_deg: 3.0,
            ..kyiv()
        };
        let at = |outer_deg, inner_deg| {
            g.orientation(TableAngles {
                outer_deg,
                inner_deg,
            })
        };
        let phi = site.latitude_deg.to_radians();
        for inner in [0.0, 90.0, 180.0, 270.0] {
            let north = at(0.0, inner);
            assert!(north.elevation_deg.abs() < 1e-9, "{north:?}");
            assert!(north.azimuth_deg.abs() < 1e-9, "{north:?}");
            assert!((north.earth_rate_dph(&site) - EARTH_RATE_DPH * phi.cos()).abs() < 1e-9);
            let up = at(90.0, inner);
            assert!((up.elevation_deg - 90.0).abs() < 1e-6, "{up:?}");
            let south = at(180.0, inner);
            assert!((south.earth_rate_dph(&site) + EARTH_RATE_DPH * phi.cos()).abs() < 1e-9);
        }
        let tilt = at(35.0, 0.0);
        assert!((tilt.elevation_deg - 35.0).abs() < 1e-9 && tilt.azimuth_deg.abs() < 1e-9);
        // The study's poses with the axis east are out of its reach, and
        // the low-latitude ones are inside it.
        assert!(g.angles_for(Orientation::new(90.0, 0.0, 0.0)).is_err());
        for roll in [0.0, 90.0, 180.0, -90.0] {
            let o = Orientation::new(0.0, 0.0, roll);
            let a = g.angles_for(o).expect("a roll about the north axis");
            assert!(rotation_distance_deg(&g.rotation(a), &o.rotation()) < 1e-6);
        }
    }

    #[test]
    fn rolls_with_axis_horizontal_turn_gravity_around_the_housing() {
        let g = TableGeometry::study();
        let mut seen = Vec::new();
        for inner in [0.0, 90.0, 180.0, 270.0] {
            let r = g.rotation(TableAngles {
                outer_deg: 0.0,
                inner_deg: inner,
            });
            let g_body = r.inverse() * gravity_ned_g();
            assert!(g_body.x.abs() < 1e-12);
            seen.push(g_body);
        }
        assert!((seen[0] + seen[2]).norm() < 1e-12);
        assert!((seen[1] + seen[3]).norm() < 1e-12);
        assert!((seen[0] - seen[1]).norm() > 1.0);
    }

    #[test]
    fn inverse_kinematics_round_trips() {
        let g = TableGeometry::study();
        for outer in [-170.0, -35.0, 0.0, 35.0, 90.0, 135.0] {
            for inner in [-90.0, 0.0, 45.0, 180.0] {
                let a = TableAngles {
                    outer_deg: outer,
                    inner_deg: inner,
                };
                let o = g.orientation(a);
                let back = g.angles_for(o).expect("reachable by construction");
                let err = rotation_distance_deg(&g.rotation(back), &g.rotation(a));
                assert!(err < 1e-6, "{a:?} -> {o:?} -> {back:?}: {err}");
            }
        }
    }

    #[test]
    fn unreachable_orientation_is_refused() {
        // Axis horizontal pointing north cannot be reached: the sensitive axis
        // always stays in the east-vertical plane on the study table.
        let err = TableGeometry::study()
            .angles_for(Orientation::new(0.0, 0.0, 0.0))
            .expect_err("north is out of reach");
        assert!(err.error_deg > 80.0, "{err}");
        assert!(err.to_string().contains("cannot reach"));
    }

    #[test]
    fn angular_velocity_of_inner_axis_lies_on_sensitive_axis() {
        let g = TableGeometry::study();
        let a = TableAngles {
            outer_deg: 90.0,
            inner_deg: 30.0,
        };
        let w = g.angular_velocity_ned_dps(
            a,
            TableAngles {
                outer_deg: 0.0,
                inner_deg: 10.0,
            },
        );
        let x = g.rotation(a) * Vector3::x();
        assert!((w.dot(&x) - 10.0).abs() < 1e-9);
    }

    /// The outer axis turning with the sensitive axis horizontal: the
    /// table rate lies across the sensitive axis, fixed in the body, on one
    /// transverse axis at the inner axis at 0 deg and on the other at 90
    /// deg (a misaligned axis reads it).
    #[test]
    fn the_outer_axis_turns_across_the_sensitive_axis() {
        let g = TableGeometry::study();
        let rates = TableAngles {
            outer_deg: 5.0,
            inner_deg: 0.0,
        };
        let mut seen = Vec::new();
        for inner in [0.0, 90.0] {
            for outer in [0.0, 37.0, 200.0] {
                let a = TableAngles {
                    outer_deg: outer,
                    inner_deg: inner,
                };
                let w = g.table_rate_body_dph(a, rates);
                assert!(w.x.abs() < 1e-9, "{w}");
                assert!((w.norm() - 18_000.0).abs() < 1e-6, "{w}");
                seen.push(w);
            }
            // Fixed in the body while the outer axis turns.
            assert!((seen[seen.len() - 1] - seen[seen.len() - 3]).norm() < 1e-6);
        }
        assert!(
            seen[0].dot(&seen[3]).abs() < 1e-6,
            "{} {}",
            seen[0],
            seen[3]
        );
    }

    /// The study's site (the twin's `fixtures/twin/rl16.toml`).
    fn study_site() -> Site {
        Site {
            latitude_deg: 50.45,
            longitude_deg: 30.52,
            height_m: 180.0,
            magnetic_field_ned_ut: [19.5, 2.7, 46.5],
        }
    }

    #[test]
    fn an_interval_reads_the_mean_of_the_turning_earth_rate_not_its_end() {
        // The axis horizontal north at the equator, the outer axis (east)
        // turning at 5 deg/s: the Earth rate on the axis is W cos(outer).
        let g = TableGeometry::north();
        let site = Site {
            latitude_deg: 0.0,
            ..study_site()
        };
        let rates = TableAngles {
            outer_deg: 5.0,
            inner_deg: 0.0,
        };
        let pose = |outer: f64| {
            (
                TableAngles {
                    outer_deg: wrap_deg(outer),
                    inner_deg: 0.0,
                },
                rates,
            )
        };
        for start in [0.0, 40.0, 87.5, 178.0, 250.0, 358.0] {
            let mean = g.mean_kinematic_rate_dph(&site, pose(start), pose(start + 5.0), 1.0);
            // The exact mean of W cos(theta) over the 5 deg.
            let (a, b) = (start.to_radians(), (start + 5.0).to_radians());
            let exact = EARTH_RATE_DPH * (b.sin() - a.sin()) / (b - a);
            assert!(
                (mean - exact).abs() < 1e-6,
                "{start}: {mean} against {exact}"
            );
            let end = g.kinematic_rate_dph(&site, pose(start + 5.0).0, rates);
            if (start + 2.5_f64).to_radians().sin().abs() > 0.5 {
                // Half a second of the turn apart: up to 0.65 deg/h.
                assert!((end - exact).abs() > 0.3, "{start}: {end} against {exact}");
            }
        }
    }

    #[test]
    fn the_interval_mean_follows_either_axis_and_a_rate_that_changes() {
        // Against a brute-force mean of the instantaneous reference along
        // the motion, on the study's table: the inner axis, both at once, a
        // spin-up, a reversal within the interval, a turn through +-180 deg,
        // a 20 ms tick.
        let g = TableGeometry::study();
        let site = study_site();
        let a = |o: f64, i: f64| TableAngles {
            outer_deg: o,
            inner_deg: i,
        };
        // (start angles, start rates, end rates, seconds)
        let cases = [
            (a(10.0, 0.0), a(0.0, 7.0), a(0.0, 7.0), 1.0),
            (a(30.0, 60.0), a(4.0, -6.0), a(4.0, -6.0), 1.0),
            (a(0.0, 90.0), a(0.0, 0.0), a(10.0, 0.0), 1.0),
            (a(20.0, 45.0), a(8.0, 0.0), a(-8.0, 0.0), 1.0),
            (a(177.0, -178.0), a(5.0, -5.0), a(5.0, -5.0), 1.0),
            (a(0.0, 0.0), a(5.0, 0.0), a(5.0, 0.0), 0.02),
        ];
        for (k, (a0, r0, r1, dt)) in cases.into_iter().enumerate() {
            // Rates linear in time, angles their integral.
            let at = |t: f64| {
                let s = t / dt;
                let ang = |x0: f64, v0: f64, v1: f64| x0 + dt * (v0 * s + 0.5 * (v1 - v0) * s * s);
                let rate = |v0: f64, v1: f64| v0 + (v1 - v0) * s;
                (
                    a(
                        ang(a0.outer_deg, r0.outer_deg, r1.outer_deg),
                        ang(a0.inner_deg, r0.inner_deg, r1.inner_deg),
                    ),
                    a(
                        rate(r0.outer_deg, r1.outer_deg),
                        rate(r0.inner_deg, r1.inner_deg),
                    ),
                )
            };
            let n = 10_000;
            let brute = (0..n)
                .map(|j| {
                    let (x, v) = at((j as f64 + 0.5) / n as f64 * dt);
                    g.kinematic_rate_dph(&site, x, v)
                })
                .sum::<f64>()
                / n as f64;
            let (x1, v1) = at(dt);
            // The end angles as a table reads them: wrapped.
            let read = a(wrap_deg(x1.outer_deg), wrap_deg(x1.inner_deg));
            let mean = g.mean_kinematic_rate_dph(&site, (a0, r0), (read, v1), dt);
            assert!(
                (mean - brute).abs() < 1e-4,
                "case {k}: {mean} against {brute}"
            );
        }
    }
}
