//! A CPU rasterizer: z-buffer, perspective-correct texture mapping (bilinear), second-order
//! spherical-harmonics diffuse lighting per vertex, alpha-tested hair, an id buffer for masks.

use crate::camera::Camera;
use glam::{Vec2, Vec3};

/// Decoded RGBA8 texture.
#[derive(Debug, Clone)]
pub struct Texture {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<[u8; 4]>,
}

impl Texture {
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        let img = image::load_from_memory(bytes)
            .map_err(|e| e.to_string())?
            .to_rgba8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let rgba = img.pixels().map(|p| p.0).collect();
        Ok(Self {
            width: w,
            height: h,
            rgba,
        })
    }

    /// Bilinear sample with wrap; `uv` (0, 0) is the bottom-left of the image (OpenGL).
    #[inline]
    pub fn sample(&self, uv: Vec2) -> [f32; 4] {
        let x = uv.x * self.width as f32 - 0.5;
        let y = (1.0 - uv.y) * self.height as f32 - 0.5;
        let (x0, y0) = (floor(x), floor(y));
        let (fx, fy) = (x - x0, y - y0);
        // Inside the image (nearly every sample) no division.
        let wrap = |v: f32, n: usize| {
            let (v, n) = (v as i64, n as i64);
            (if (0..n).contains(&v) {
                v
            } else {
                v.rem_euclid(n)
            }) as usize
        };
        let (xa, xb) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let (ya, yb) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let t = |x: usize, y: usize| self.rgba[y * self.width + x];
        let (a, b, c, d) = (t(xa, ya), t(xb, ya), t(xa, yb), t(xb, yb));
        let mut out = [0.0; 4];
        for k in 0..4 {
            let top = a[k] as f32 + (b[k] as f32 - a[k] as f32) * fx;
            let bot = c[k] as f32 + (d[k] as f32 - c[k] as f32) * fx;
            out[k] = (top + (bot - top) * fy) / 255.0;
        }
        out
    }
}

/// `x.floor()` for |x| < 2^63 (texture coordinates), without the call into libm that
/// `f32::floor` is on x86-64's baseline; NaN gives 0 (the sample's weights stay NaN).
#[inline]
fn floor(x: f32) -> f32 {
    let t = x as i64 as f32;
    if t > x { t - 1.0 } else { t }
}

/// Irradiance as second-order real spherical harmonics, per colour channel:
/// `E(n) = sum_k coeffs[k] * Y_k(n)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sh9 {
    pub coeffs: [[f32; 3]; 9],
}

fn sh_basis(n: Vec3) -> [f32; 9] {
    let (x, y, z) = (n.x, n.y, n.z);
    [
        0.282_095,
        0.488_603 * y,
        0.488_603 * z,
        0.488_603 * x,
        1.092_548 * x * y,
        1.092_548 * y * z,
        0.315_392 * (3.0 * z * z - 1.0),
        1.092_548 * x * z,
        0.546_274 * (x * x - y * y),
    ]
}

impl Sh9 {
    /// Constant irradiance `a`.
    pub fn ambient(a: [f32; 3]) -> Self {
        let mut coeffs = [[0.0; 3]; 9];
        for c in 0..3 {
            coeffs[0][c] = a[c] / 0.282_095;
        }
        Self { coeffs }
    }

    /// Add a directional light from `dir` (towards the light) whose irradiance on a facing
    /// surface is `color` (Ramamoorthi & Hanrahan's band-2 clamped-cosine approximation).
    pub fn add_directional(&mut self, dir: Vec3, color: [f32; 3]) {
        let l = dir.normalize_or(Vec3::Y);
        let y = sh_basis(l);
        let a_hat = [
            std::f32::consts::PI,
            2.0 * std::f32::consts::PI / 3.0,
            2.0 * std::f32::consts::PI / 3.0,
            2.0 * std::f32::consts::PI / 3.0,
            std::f32::consts::PI / 4.0,
            std::f32::consts::PI / 4.0,
            std::f32::consts::PI / 4.0,
            std::f32::consts::PI / 4.0,
            std::f32::consts::PI / 4.0,
        ];
        for ((coef, a), yk) in self.coeffs.iter_mut().zip(a_hat).zip(y) {
            for (cc, col) in coef.iter_mut().zip(color) {
                *cc += col * a * yk / std::f32::consts::PI;
            }
        }
    }

    #[inline]
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        let y = sh_basis(n);
        let e: Vec3 = self
            .coeffs
            .iter()
            .zip(y)
            .map(|(c, yk)| Vec3::from_array(*c) * yk)
            .sum();
        e.max(Vec3::ZERO)
    }
}

/// A frame being drawn: colour (linear, [0, 1]), depth along the view direction (infinite
/// where empty), and an id per pixel (0 = background).
#[derive(Debug, Clone)]
pub struct Framebuffer {
    pub width: usize,
    pub height: usize,
    pub color: Vec<[f32; 3]>,
    pub depth: Vec<f32>,
    pub id: Vec<u8>,
}

impl Framebuffer {
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            color: vec![[0.0; 3]; width * height],
            depth: vec![f32::INFINITY; width * height],
            id: vec![0; width * height],
        }
    }

    /// Reset to `background` (same size), keeping allocations.
    pub fn clear(&mut self, background: &[[f32; 3]]) {
        self.color.copy_from_slice(background);
        self.depth.fill(f32::INFINITY);
        self.id.fill(0);
    }
}

/// One mesh to draw.
pub struct DrawMesh<'a> {
    pub verts: &'a [Vec3],
    pub normals: &'a [Vec3],
    pub tris: &'a [[u32; 3]],
    pub uv_tris: &'a [[u32; 3]],
    pub uvs: &'a [[f32; 2]],
    pub texture: Option<&'a Texture>,
    pub color: [f32; 3],
    /// Alpha-test texels below 0.5 (hair cards).
    pub alpha_test: bool,
    /// Skip triangles facing away (closed meshes); open shells are drawn two-sided.
    pub cull_back: bool,
    pub id: u8,
}

/// Per-vertex scratch reused across draws.
#[derive(Default)]
pub struct Rasterizer {
    scr: Vec<(f32, f32, f32, f32)>,
    light: Vec<Vec3>,
}

/// Smooth vertex normals of a triangle mesh (area-weighted), written into `out`.
pub fn vertex_normals(verts: &[Vec3], tris: &[[u32; 3]], out: &mut Vec<Vec3>) {
    out.clear();
    out.resize(verts.len(), Vec3::ZERO);
    for t in tris {
        let [a, b, c] = t.map(|i| verts[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            out[i as usize] += n;
        }
    }
    for n in out.iter_mut() {
        *n = n.normalize_or(Vec3::Y);
    }
}

impl Rasterizer {
    pub fn draw(&mut self, fb: &mut Framebuffer, cam: &Camera, sh: &Sh9, m: &DrawMesh) {
        let persp = cam.is_perspective();
        let proj = cam.projector();
        self.scr.clear();
        self.scr.extend(m.verts.iter().map(|v| {
            let s = proj.to_screen(*v);
            let inv_w = if persp { 1.0 / s.depth.max(1e-6) } else { 1.0 };
            (s.px, s.py, s.depth, inv_w)
        }));
        self.light.clear();
        self.light
            .extend(m.normals.iter().map(|n| sh.irradiance(*n)));
        let (w, h) = (fb.width as i64, fb.height as i64);
        let base = Vec3::from_array(m.color);
        for (ti, t) in m.tris.iter().enumerate() {
            let [i0, i1, mut i2] = t.map(|i| i as usize);
            let (mut a, mut b, mut c) = (self.scr[i0], self.scr[i1], self.scr[i2]);
            if a.2 < cam.near || b.2 < cam.near || c.2 < cam.near {
                continue;
            }
            let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            // Front faces have negative screen area (y down).
            if m.cull_back && area > 0.0 {
                continue;
            }
            let uvt = m.uv_tris.get(ti).copied().unwrap_or([0; 3]);
            let (u0, mut u1, mut u2) = (uvt[0] as usize, uvt[1] as usize, uvt[2] as usize);
            let mut i1 = i1;
            let area = if area < 0.0 {
                std::mem::swap(&mut b, &mut c);
                std::mem::swap(&mut i1, &mut i2);
                std::mem::swap(&mut u1, &mut u2);
                -area
            } else {
                area
            };
            let _ = &mut a;
            let inv_area = 1.0 / area;
            let x0 = (a.0.min(b.0).min(c.0).ceil() as i64).max(0);
            let x1 = (a.0.max(b.0).max(c.0).floor() as i64).min(w - 1);
            let y0 = (a.1.min(b.1).min(c.1).ceil() as i64).max(0);
            let y1 = (a.1.max(b.1).max(c.1).floor() as i64).min(h - 1);
            if x0 > x1 || y0 > y1 {
                continue;
            }
            let uv = |k: usize| {
                m.uvs
                    .get(k)
                    .map(|u| Vec2::from_array(*u))
                    .unwrap_or(Vec2::ZERO)
            };
            let (uva, uvb, uvc) = (uv(u0), uv(u1), uv(u2));
            let (la, lb, lc) = (self.light[i0], self.light[i1], self.light[i2]);
            // Edge functions e_a (opposite a) etc., stepped per pixel.
            let ea = |x: f32, y: f32| (c.0 - b.0) * (y - b.1) - (c.1 - b.1) * (x - b.0);
            let eb = |x: f32, y: f32| (a.0 - c.0) * (y - c.1) - (a.1 - c.1) * (x - c.0);
            let ec = |x: f32, y: f32| (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0);
            let (dax, dbx, dcx) = (-(c.1 - b.1), -(a.1 - c.1), -(b.1 - a.1));
            for y in y0..=y1 {
                let yf = y as f32;
                let (mut wa, mut wb, mut wc) =
                    (ea(x0 as f32, yf), eb(x0 as f32, yf), ec(x0 as f32, yf));
                let row = (y * w) as usize;
                for x in x0..=x1 {
                    if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
                        let (ba, bb, bc) = (wa * inv_area, wb * inv_area, wc * inv_area);
                        let q = ba * a.3 + bb * b.3 + bc * c.3;
                        let (pa, pb, pc) = (ba * a.3 / q, bb * b.3 / q, bc * c.3 / q);
                        let depth = pa * a.2 + pb * b.2 + pc * c.2;
                        let idx = row + x as usize;
                        if depth < fb.depth[idx] {
                            let mut alb = base;
                            let mut keep = true;
                            if let Some(tex) = m.texture {
                                let t = tex.sample(uva * pa + uvb * pb + uvc * pc);
                                alb *= Vec3::new(t[0], t[1], t[2]);
                                keep = !m.alpha_test || t[3] >= 0.5;
                            }
                            if keep {
                                let e = la * pa + lb * pb + lc * pc;
                                fb.depth[idx] = depth;
                                fb.color[idx] = (alb * e).min(Vec3::ONE).to_array();
                                fb.id[idx] = m.id;
                            }
                        }
                    }
                    wa += dax;
                    wb += dbx;
                    wc += dcx;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sampler's floor is `f32::floor` on texture coordinates: integers, halves, ulps
    /// either side of integers, negatives (wrapped coordinates) and large values.
    #[test]
    fn floor_is_f32_floor() {
        let mut xs = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1e9,
            -1e9,
            16_777_217.0,
            -3.999_999_8,
        ];
        for k in -70..70 {
            let x = k as f32 * 0.75;
            let up = f32::from_bits(x.to_bits() + 1);
            let down = if x == 0.0 {
                -f32::MIN_POSITIVE
            } else {
                f32::from_bits(x.to_bits() - 1)
            };
            xs.extend([x, up, down, x + 0.5]);
        }
        for x in xs {
            assert_eq!(floor(x), x.floor(), "x = {x:e}");
        }
        assert_eq!(floor(f32::NAN), 0.0);
    }

    /// Texel centres give the texel; a coordinate one width over wraps to the same texel.
    #[test]
    fn sample_hits_texel_centres_and_wraps() {
        let tex = Texture {
            width: 2,
            height: 2,
            rgba: vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 0],
            ],
        };
        // Row 0 of the image is the top: v = 0.75 is its centre, u = 0.25 the first column.
        assert_eq!(tex.sample(Vec2::new(0.25, 0.75)), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(tex.sample(Vec2::new(0.75, 0.75)), [0.0, 1.0, 0.0, 1.0]);
        assert_eq!(tex.sample(Vec2::new(-0.75, 0.25)), [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(tex.sample(Vec2::new(1.75, -0.75)), [1.0, 1.0, 1.0, 0.0]);
        // Halfway between the two top texels: their mean.
        assert_eq!(tex.sample(Vec2::new(0.5, 0.75)), [0.5, 0.5, 0.0, 1.0]);
    }
}
