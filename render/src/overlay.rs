//! Lines drawn over a rendered image: the simulation cell's edges (`--cell`).
//!
//! How it works. Each segment is sampled in world space about twice per pixel of its
//! projected length; each sample is projected with the camera's (unjittered) matrix and
//! kept where it lies in front of the surface the frame drew at its pixel: the frame's
//! depth is taken back to a distance along the view direction and compared with the
//! sample's, with a bias (the largest particle radius) so that atoms sitting on the
//! cell's faces do not hide its edges. Kept samples stamp an antialiased disc of the
//! line's width into a coverage buffer, which is composited over the image once, so
//! overlapping stamps do not darken the line. Without a depth buffer (splats, the
//! volume), every sample in front of the near plane is kept.

use glam::{Vec2, Vec3, Vec4Swizzles};
use mdlod_format::meta::SimulationBox;

use crate::camera::Camera;
use crate::image::RgbaImage;

/// The twelve edges of a (possibly triclinic) cell: corners `origin + i a + j b + k c`.
pub fn cell_edges(cell: &SimulationBox) -> Vec<[Vec3; 2]> {
    let v = |a: [f64; 3]| Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32);
    let (o, a, b, c) = (v(cell.origin), v(cell.a), v(cell.b), v(cell.c));
    let corner = |i: u32, j: u32, k: u32| o + a * i as f32 + b * j as f32 + c * k as f32;
    let mut edges = Vec::with_capacity(12);
    for i in 0..2 {
        for j in 0..2 {
            edges.push([corner(0, i, j), corner(1, i, j)]);
            edges.push([corner(i, 0, j), corner(i, 1, j)]);
            edges.push([corner(i, j, 0), corner(i, j, 1)]);
        }
    }
    edges
}

/// Draws `lines` over `image` (sRGB `colour`, `width_px` wide), hidden where the frame's
/// `depth` (as [`crate::RenderedFrame::depth`]) shows a surface nearer than the line by
/// more than `bias` world units.
pub fn draw_lines(
    image: &mut RgbaImage,
    depth: Option<&[f32]>,
    camera: &Camera,
    lines: &[[Vec3; 2]],
    colour: [u8; 3],
    width_px: f32,
    bias: f32,
) {
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return;
    }
    let clip_from_world = camera.clip_from_world([w, h], Vec2::ZERO);
    let view_from_clip = camera.clip_from_view(w as f32 / h as f32).inverse();
    let forward = -camera.back();
    let eye = camera.eye();
    let half = (width_px * 0.5).max(0.5);
    let mut cover = vec![0.0f32; (w * h) as usize];
    // The pixel position and NDC depth of a world point, when it lies inside the depth
    // range (and, in perspective, in front of the eye).
    let project = |p: Vec3| -> Option<(Vec2, f32)> {
        let c = clip_from_world * p.extend(1.0);
        if c.w <= 0.0 {
            return None;
        }
        let ndc = c.xyz() / c.w;
        (0.0..=1.0).contains(&ndc.z).then(|| {
            (
                Vec2::new(
                    (ndc.x + 1.0) * 0.5 * w as f32,
                    (1.0 - ndc.y) * 0.5 * h as f32,
                ),
                ndc.z,
            )
        })
    };
    for &[p0, p1] in lines {
        // Samples about every half pixel of the projected segment (ends clipped away
        // count as the image's size).
        let length_px = match (project(p0), project(p1)) {
            (Some((a, _)), Some((b, _))) => a.distance(b),
            _ => (w + h) as f32,
        };
        let n = (length_px * 2.0).ceil().clamp(2.0, 65_536.0) as usize;
        for s in 0..=n {
            let p = p0.lerp(p1, s as f32 / n as f32);
            let Some((xy, _)) = project(p) else { continue };
            let (px, py) = (xy.x.floor(), xy.y.floor());
            if px < -half || py < -half || px >= w as f32 + half || py >= h as f32 + half {
                continue;
            }
            // Hidden behind the surface drawn at this pixel?
            if let Some(depth) = depth {
                let (ix, iy) = (px.clamp(0.0, (w - 1) as f32), py.clamp(0.0, (h - 1) as f32));
                let z = depth[(iy as u32 * w + ix as u32) as usize];
                if z < 1.0 {
                    let ndc = Vec2::new(
                        (ix + 0.5) / w as f32 * 2.0 - 1.0,
                        1.0 - (iy + 0.5) / h as f32 * 2.0,
                    );
                    let v = view_from_clip * ndc.extend(z).extend(1.0);
                    let surface = -(v.z / v.w);
                    if (p - eye).dot(forward) > surface + bias {
                        continue;
                    }
                }
            }
            // An antialiased disc of the line's width.
            let r = half + 1.0;
            let (x0, x1) = ((xy.x - r).floor().max(0.0), (xy.x + r).ceil().min(w as f32));
            let (y0, y1) = ((xy.y - r).floor().max(0.0), (xy.y + r).ceil().min(h as f32));
            let (mut y, mut x);
            y = y0;
            while y < y1 {
                x = x0;
                while x < x1 {
                    let d = Vec2::new(x + 0.5, y + 0.5).distance(xy);
                    let a = (half + 0.5 - d).clamp(0.0, 1.0);
                    let k = (y as u32 * w + x as u32) as usize;
                    cover[k] = cover[k].max(a);
                    x += 1.0;
                }
                y += 1.0;
            }
        }
    }
    for (k, &a) in cover.iter().enumerate() {
        image.blend_over(k as u32 % w, k as u32 / w, colour, a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Projection;

    fn camera() -> Camera {
        // Looking down -z at the origin from 10 units, orthographic: the view's x is the
        // world's x.
        let mut c = Camera {
            projection: Projection::Orthographic,
            elevation_deg: 90.0,
            azimuth_deg: -90.0,
            ..Default::default()
        };
        c.fit(&crate::Bounds::new([-1.0; 3], [1.0; 3]), 1.0);
        c
    }

    fn drawn(image: &RgbaImage) -> usize {
        image.data.chunks(4).filter(|p| p[0] < 128).count()
    }

    #[test]
    fn a_triclinic_cell_has_twelve_edges_along_its_vectors() {
        let cell = SimulationBox {
            origin: [1.0, 2.0, 3.0],
            a: [4.0, 0.0, 0.0],
            b: [1.0, 3.0, 0.0],
            c: [0.5, 0.5, 2.0],
            periodic: None,
        };
        let edges = cell_edges(&cell);
        assert_eq!(edges.len(), 12);
        for v in [cell.a, cell.b, cell.c] {
            let v = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
            assert_eq!(
                edges
                    .iter()
                    .filter(|[p, q]| (*q - *p - v).length() < 1e-5)
                    .count(),
                4
            );
        }
        assert!(edges.iter().any(|[p, _]| *p == Vec3::new(1.0, 2.0, 3.0)));
    }

    /// A line across the view is drawn where nothing hides it: everywhere without a
    /// depth buffer or over an empty one, nowhere behind a surface at the near plane,
    /// and where a surface lies just behind it (the bias keeps atoms on the cell's faces
    /// from hiding its edges).
    #[test]
    fn lines_are_drawn_where_no_surface_hides_them() {
        let c = camera();
        let (w, h) = (64u32, 64u32);
        let line = [[Vec3::new(-0.8, 0.0, 0.0), Vec3::new(0.8, 0.0, 0.0)]];
        let white = || {
            let mut i = RgbaImage::new(w, h);
            i.data.fill(255);
            i
        };
        let mut free = white();
        draw_lines(&mut free, None, &c, &line, [0, 0, 0], 2.0, 0.0);
        // 1.6 of the view's 2 / 0.9 (the fitted box fills 90 %): about 46 px long, 2
        // wide.
        let n = drawn(&free);
        assert!((80..=110).contains(&n), "{n}");
        // Pixels of the middle row are black (the line's discs, every half pixel along
        // it, cover a pixel the line crosses to at least 94 %), those far from it
        // untouched.
        assert!(free.pixel(w / 2, h / 2)[..3].iter().all(|&v| v < 16));
        assert_eq!(free.pixel(w / 2, 5), [255; 4]);
        let mut empty = white();
        draw_lines(
            &mut empty,
            Some(&vec![1.0; (w * h) as usize]),
            &c,
            &line,
            [0, 0, 0],
            2.0,
            0.0,
        );
        assert_eq!(empty.data, free.data);
        let mut hidden = white();
        draw_lines(
            &mut hidden,
            Some(&vec![0.0; (w * h) as usize]),
            &c,
            &line,
            [0, 0, 0],
            2.0,
            0.0,
        );
        assert_eq!(drawn(&hidden), 0);
        // A surface 0.05 in front of the line (the eye is above, at +z): the line is
        // kept with a bias of 0.1, hidden without.
        let line_z = {
            let m = c.clip_from_world([w, h], Vec2::ZERO);
            let p = m * Vec3::new(0.0, 0.0, 0.05).extend(1.0);
            p.z / p.w
        };
        let mut near = white();
        draw_lines(
            &mut near,
            Some(&vec![line_z; (w * h) as usize]),
            &c,
            &line,
            [0, 0, 0],
            2.0,
            0.1,
        );
        assert_eq!(near.data, free.data);
        let mut far = white();
        draw_lines(
            &mut far,
            Some(&vec![line_z; (w * h) as usize]),
            &c,
            &line,
            [0, 0, 0],
            2.0,
            0.0,
        );
        assert_eq!(drawn(&far), 0);
    }
}
