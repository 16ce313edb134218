//! Small 3-D rotation helpers in `f64` (column vectors, right-handed).

use crate::clip::Axis;

/// A 3×3 matrix, row-major: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];
/// A 3-vector.
pub type Vec3 = [f64; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Rotation by `angle_deg` about a coordinate axis.
pub fn rot_axis(axis: Axis, angle_deg: f64) -> Mat3 {
    let (s, c) = angle_deg.to_radians().sin_cos();
    match axis {
        Axis::X => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        Axis::Y => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        Axis::Z => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// Matrix product `a · b`.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    r
}

/// Transpose (the inverse of a rotation).
pub fn transpose(a: &Mat3) -> Mat3 {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// Matrix times column vector.
pub fn mul_vec(a: &Mat3, v: &Vec3) -> Vec3 {
    [
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    ]
}

/// Vector sum.
pub fn add(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Rotations about fixed axes applied in the listed order (the ASF reading): for the list
/// `(a1, a2, a3)` the result is `R(a3) · R(a2) · R(a1)`, so `XYZ` gives `Rz · Ry · Rx`.
pub fn euler_fixed(axes: &[Axis], angles_deg: &[f64]) -> Mat3 {
    let mut r = IDENTITY;
    for (&axis, &angle) in axes.iter().zip(angles_deg) {
        r = mul(&rot_axis(axis, angle), &r);
    }
    r
}

/// Rotations composed in listed order (the BVH reading): for `(a1, a2, a3)` the result is
/// `R(a1) · R(a2) · R(a3)`, so `Zrotation Yrotation Xrotation` gives `Rz · Ry · Rx`.
pub fn euler_listed(axes: &[Axis], angles_deg: &[f64]) -> Mat3 {
    let mut r = IDENTITY;
    for (&axis, &angle) in axes.iter().zip(angles_deg) {
        r = mul(&r, &rot_axis(axis, angle));
    }
    r
}

/// Decomposes a rotation into `R = Rz(z) · Ry(y) · Rx(x)` and returns `[z, y, x]` in degrees.
///
/// At gimbal lock (|y| = 90°) the split between z and x is arbitrary; x is set to 0.
pub fn to_euler_zyx_deg(r: &Mat3) -> [f64; 3] {
    let sy = (-r[2][0]).clamp(-1.0, 1.0);
    let y = sy.asin();
    if sy.abs() > 1.0 - 1e-12 {
        let z = (-r[0][1]).atan2(r[1][1]);
        [z.to_degrees(), y.to_degrees(), 0.0]
    } else {
        let z = r[1][0].atan2(r[0][0]);
        let x = r[2][1].atan2(r[2][2]);
        [z.to_degrees(), y.to_degrees(), x.to_degrees()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3, b: &Mat3) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() < 1e-12))
    }

    #[test]
    fn fixed_and_listed_orders_are_mirror_images() {
        let axes = [Axis::X, Axis::Y, Axis::Z];
        let angles = [10.0, -20.0, 35.0];
        let fixed = euler_fixed(&axes, &angles);
        let expect = mul(
            &rot_axis(Axis::Z, 35.0),
            &mul(&rot_axis(Axis::Y, -20.0), &rot_axis(Axis::X, 10.0)),
        );
        assert!(close(&fixed, &expect));
        let listed = euler_listed(&[Axis::Z, Axis::Y, Axis::X], &[35.0, -20.0, 10.0]);
        assert!(close(&listed, &expect));
    }

    #[test]
    fn zyx_decomposition_round_trips() {
        for &(z, y, x) in &[
            (10.0, 20.0, 30.0),
            (-170.0, 80.0, 5.0),
            (45.0, -60.0, -120.0),
        ] {
            let r = euler_listed(&[Axis::Z, Axis::Y, Axis::X], &[z, y, x]);
            let [z2, y2, x2] = to_euler_zyx_deg(&r);
            let r2 = euler_listed(&[Axis::Z, Axis::Y, Axis::X], &[z2, y2, x2]);
            assert!(close(&r, &r2));
        }
    }

    #[test]
    fn rotation_about_z_turns_x_into_y() {
        let v = mul_vec(&rot_axis(Axis::Z, 90.0), &[1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15);
        assert!(close(
            &mul(
                &rot_axis(Axis::Y, 33.0),
                &transpose(&rot_axis(Axis::Y, 33.0))
            ),
            &IDENTITY
        ));
    }
}
