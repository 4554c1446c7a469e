//! The hands' poses: the forearm's twist, the wrist's flexion and deviation and the fingers'
//! curl, for the procedural generator's `hands = "varied"` (a scene's motion, a dataset's or
//! an evaluation's `--hands varied`). Without it every hand keeps the rest pose's: open,
//! hanging from a straight wrist, the palm towards the thigh.
//!
//! The axes come from the subject's rest joints (mesh frame, decimetres; y up, the character
//! faces +z, +x is its left), so that a rotation by the same angle on the left and on the
//! right gives mirror images:
//! - the hand's direction `d`: the wrist's head to the middle finger's last joint;
//! - `across`: the index finger's knuckle to the little finger's, made orthogonal to `d`;
//! - the palm's normal (where the palm faces): `across x d` on the left, `d x across` on the
//!   right (at rest it faces the thigh: -x on the left, +x on the right; tested);
//! - the flexion axis of a finger or the wrist: `d x palm` (a positive angle brings the
//!   fingers or the hand towards the palm).
//!
//! Angles (degrees, [`crate::pose::Angles`]): `finger_curl` is the knuckles' flexion, the
//! middle joints take 1.1 times it and the last 0.75 times (a fist at 90), the thumb half;
//! `wrist_flex` towards the palm (negative: extension), `wrist_dev` towards the little finger
//! (ulnar; negative: radial), `forearm_twist` pronation (the palm turns backward; negative:
//! supination).

use crate::assets::HumanAssets;
use glam::{Mat3, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

/// How a procedural motion poses the hands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Hands {
    /// The rest pose's hands (every dataset and evaluation before 2026-12-02).
    #[default]
    Rest,
    /// Seeded wrist, forearm and finger poses ([`HandDraw`]).
    Varied,
}

impl Hands {
    pub const ALL: [Hands; 2] = [Hands::Rest, Hands::Varied];

    /// The name in scene files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Hands::Rest => "rest",
            Hands::Varied => "varied",
        }
    }
}

impl std::str::FromStr for Hands {
    type Err = String;

    /// By [`Hands::name`]; anything else is refused naming the value and the choices.
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|h| h.name() == s)
            .ok_or_else(|| format!("hands {s:?}: expected rest or varied"))
    }
}

/// The salt of the hands' own random stream: a motion's body angles are the same whether its
/// hands are drawn or not.
const HAND_SALT: u64 = 0x6861_6e64_7321;

/// One motion's drawn hand poses: a base pose per side and a slow sway around it.
#[derive(Debug, Clone, PartialEq)]
pub struct HandDraw {
    /// [left, right] (degrees).
    pub curl: [f32; 2],
    pub flex: [f32; 2],
    pub dev: [f32; 2],
    pub twist: [f32; 2],
    phase: [f32; 2],
}

impl HandDraw {
    /// The draw of a motion's `seed`: the knuckles' curl uniform in [0, 90] (open hand to
    /// fist), the wrist's flexion in [-45, 55], its deviation in [-15, 25], the forearm's twist
    /// in [-70, 80]; each side on its own.
    pub fn new(seed: u64) -> Self {
        let mut r = ChaCha8Rng::seed_from_u64(seed ^ HAND_SALT);
        let mut two = |lo: f32, hi: f32| [r.random_range(lo..hi), r.random_range(lo..hi)];
        let curl = two(0.0, 90.0);
        let flex = two(-45.0, 55.0);
        let dev = two(-15.0, 25.0);
        let twist = two(-70.0, 80.0);
        let phase = two(0.0, std::f32::consts::TAU);
        Self {
            curl,
            flex,
            dev,
            twist,
            phase,
        }
    }

    /// Write the hand angles at motion phase `ph` (radians) into `a`: the base pose and a
    /// sway of 10 degrees of curl and flexion, 15 of twist (the limits apply after).
    pub fn apply(&self, ph: f32, a: &mut crate::pose::Angles) {
        for s in 0..2 {
            let w = (ph + self.phase[s]).sin();
            a.finger_curl[s] = self.curl[s] + 10.0 * w;
            a.wrist_flex[s] = self.flex[s] + 10.0 * w;
            a.wrist_dev[s] = self.dev[s];
            a.forearm_twist[s] = self.twist[s] + 15.0 * w;
        }
    }
}

/// One finger's joints (knuckle to tip) and its flexion axis.
#[derive(Debug, Clone)]
struct Finger {
    joints: [Option<usize>; 3],
    axis: Vec3,
    /// The thumb bends half as far.
    scale: f32,
}

/// One side's hand bones and rest axes.
#[derive(Debug, Clone)]
struct Side {
    twist_bone: Option<usize>,
    twist_axis: Vec3,
    wrist: Option<usize>,
    flex_axis: Vec3,
    palm: Vec3,
    fingers: Vec<Finger>,
}

/// The bones and axes the hand angles drive, from a subject's rest joints.
#[derive(Debug, Clone)]
pub struct HandRig {
    sides: [Option<Side>; 2],
}

/// The flexion of a finger's three joints per degree of curl.
const JOINT_SHARE: [f32; 3] = [1.0, 1.1, 0.75];

impl HandRig {
    pub fn new(assets: &HumanAssets, heads: &[Vec3]) -> Self {
        let find = |n: String| assets.bones.iter().position(|b| b.name == n);
        // A side whose rig lacks the joints that frame the hand drives none of its bones.
        let side = |s: usize| -> Option<Side> {
            let sx = if s == 0 { "L" } else { "R" };
            let bone = |base: &str| find(format!("{base}.{sx}"));
            let head = |b: Option<usize>| b.and_then(|b| heads.get(b).copied());
            let wrist = bone("wrist");
            let w = head(wrist)?;
            let d = (head(bone("finger3-3"))? - w).normalize_or(Vec3::NEG_Y);
            let across = head(bone("finger5-1"))? - head(bone("finger2-1"))?;
            let across = (across - d * across.dot(d)).normalize_or(d.any_orthonormal_vector());
            let palm = if s == 0 {
                across.cross(d)
            } else {
                d.cross(across)
            };
            let flex_of = |dir: Vec3| dir.cross(palm).normalize_or(d.cross(palm));
            let twist_axis = head(bone("lowerarm01")).map_or(d, |e| (w - e).normalize_or(d));
            let fingers = (1..=5)
                .map(|k| {
                    let joints = [1, 2, 3].map(|j| bone(&format!("finger{k}-{j}")));
                    let dir = match (head(joints[0]), head(joints[2])) {
                        (Some(a), Some(b)) => (b - a).normalize_or(d),
                        _ => d,
                    };
                    Finger {
                        joints,
                        axis: flex_of(dir),
                        scale: if k == 1 { 0.5 } else { 1.0 },
                    }
                })
                .collect();
            Some(Side {
                twist_bone: bone("lowerarm02"),
                twist_axis,
                wrist,
                flex_axis: flex_of(d),
                palm,
                fingers,
            })
        };
        Self {
            sides: [side(0), side(1)],
        }
    }

    /// Where the palm of side `s` (0 left, 1 right) faces at rest (unit, mesh frame); none
    /// where the rig lacks that hand's joints.
    pub fn palm(&self, s: usize) -> Option<Vec3> {
        self.sides[s.min(1)].as_ref().map(|side| side.palm)
    }

    /// Set the hand bones' rotations for `a` in `out` (per bone, parent-relative, mesh-frame
    /// axes; `out` holds every bone). Angles of zero leave the bones at identity.
    pub fn rotations(&self, a: &crate::pose::Angles, out: &mut [Mat3]) {
        let r = |d: f32| d.to_radians();
        for (s, side) in self.sides.iter().enumerate() {
            let Some(side) = side else { continue };
            // Rotations about the polar axes (the forearm's, the palm's) turn the other way
            // on the right to mirror the left.
            let sign = if s == 0 { 1.0 } else { -1.0 };
            let mut set = |b: Option<usize>, m: Mat3| {
                if let Some(slot) = b.and_then(|b| out.get_mut(b)) {
                    *slot = m;
                }
            };
            if a.forearm_twist[s] != 0.0 {
                let m = Mat3::from_axis_angle(side.twist_axis, sign * r(a.forearm_twist[s]));
                set(side.twist_bone, m);
            }
            if a.wrist_flex[s] != 0.0 || a.wrist_dev[s] != 0.0 {
                // Ulnar deviation turns the hand towards `across` (the little finger): about
                // the palm's normal by minus the angle on the left (module docs).
                let dev = Mat3::from_axis_angle(side.palm, -sign * r(a.wrist_dev[s]));
                let flex = Mat3::from_axis_angle(side.flex_axis, r(a.wrist_flex[s]));
                set(side.wrist, dev * flex);
            }
            if a.finger_curl[s] != 0.0 {
                for f in &side.fingers {
                    for (j, share) in f.joints.iter().zip(JOINT_SHARE) {
                        let m =
                            Mat3::from_axis_angle(f.axis, r(a.finger_curl[s] * share * f.scale));
                        set(*j, m);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::{Angles, Procedural, Rig, Style};
    use crate::subject::{Posed, Subject, SubjectSpec};

    struct Body {
        assets: HumanAssets,
        subject: Subject,
        rig: Rig,
        /// Each base-mesh vertex's most weighted bone.
        bone_of: Vec<usize>,
    }

    impl Body {
        fn new() -> Self {
            let assets = HumanAssets::embedded().unwrap();
            let subject = Subject::new(&assets, &SubjectSpec::default()).unwrap();
            let rig = Rig::new(&assets, &subject.heads);
            let bone_of = assets
                .weights
                .iter()
                .map(|w| {
                    w.iter()
                        .max_by(|a, b| a.1.total_cmp(&b.1))
                        .map_or(usize::MAX, |(b, _)| *b as usize)
                })
                .collect();
            Self {
                assets,
                subject,
                rig,
                bone_of,
            }
        }

        fn bone(&self, name: &str) -> usize {
            self.assets
                .bones
                .iter()
                .position(|b| b.name == name)
                .unwrap_or_else(|| panic!("no bone {name}"))
        }

        fn posed(&self, a: &Angles) -> Posed {
            let (mut rot, mut posed) = (Vec::new(), Posed::default());
            self.rig.rotations(a, &mut rot);
            self.subject.pose(&self.assets, &rot, &mut posed);
            posed
        }

        /// A bone's rest head where `rest` (the rest pose) puts it: metres, feet on the floor.
        fn head_m(&self, rest: &Posed, name: &str) -> Vec3 {
            let shift_dm = rest.verts[0] * 10.0 - self.subject.rest[0];
            (self.subject.heads[self.bone(name)] + shift_dm) * 0.1
        }

        /// The centroid (metres, feet on the floor) of the vertices `name` weighs most.
        fn centroid(&self, posed: &Posed, name: &str) -> Vec3 {
            let b = self.bone(name);
            let (mut sum, mut n) = (Vec3::ZERO, 0.0f32);
            for (i, &bo) in self.bone_of.iter().enumerate() {
                if bo == b {
                    sum += posed.verts[i];
                    n += 1.0;
                }
            }
            assert!(n > 0.0, "no vertex follows {name}");
            sum / n
        }
    }

    fn both(v: f32) -> [f32; 2] {
        [v, v]
    }

    #[test]
    fn the_palms_face_the_thighs_at_rest() {
        // The rest pose's hands hang with the palms towards the body: -x on the left (+x is
        // the character's left), +x on the right.
        let body = Body::new();
        let (l, r) = (body.rig.palm(0).unwrap(), body.rig.palm(1).unwrap());
        assert!(l.x < -0.7 && r.x > 0.7, "palms {l} {r}");
        assert!((l.length() - 1.0).abs() < 1e-4 && (r.length() - 1.0).abs() < 1e-4);
    }

    #[test]
    fn angles_of_zero_leave_the_rest_pose() {
        let body = Body::new();
        let mut rot = Vec::new();
        body.rig.rotations(&Angles::default(), &mut rot);
        assert!(rot.iter().all(|m| *m == Mat3::IDENTITY));
    }

    #[test]
    fn drawn_hands_leave_the_bodys_motion_as_it_was() {
        for style in Style::ALL {
            for seed in 0..8 {
                let rest = Procedural::new(style, seed, 1.3);
                let drawn = rest.clone().with_hands(Hands::Varied);
                assert_eq!(rest.hands(), Hands::Rest);
                assert_eq!(drawn.hands(), Hands::Varied);
                for k in 0..20 {
                    let t = k as f32 * 0.11;
                    let (a, b) = (rest.angles(t), drawn.angles(t));
                    assert_eq!(a.forearm_twist, [0.0; 2]);
                    assert_eq!(a.finger_curl, [0.0; 2]);
                    assert_eq!(b, b.limited(), "{style:?} {seed}");
                    let body_only = Angles {
                        forearm_twist: a.forearm_twist,
                        wrist_flex: a.wrist_flex,
                        wrist_dev: a.wrist_dev,
                        finger_curl: a.finger_curl,
                        ..b
                    };
                    assert_eq!(a, body_only, "{style:?} {seed}: the body moved");
                }
            }
        }
        // The draw spans open hands and fists, and both ways of the wrist and forearm.
        let draws: Vec<HandDraw> = (0..200).map(HandDraw::new).collect();
        let span = |f: &dyn Fn(&HandDraw) -> [f32; 2]| {
            let v: Vec<f32> = draws.iter().flat_map(f).collect();
            (
                v.iter().copied().fold(f32::MAX, f32::min),
                v.iter().copied().fold(f32::MIN, f32::max),
            )
        };
        let (lo, hi) = span(&|d| d.curl);
        assert!(lo < 5.0 && hi > 85.0, "curl {lo}..{hi}");
        let (lo, hi) = span(&|d| d.flex);
        assert!(lo < -40.0 && hi > 50.0, "flex {lo}..{hi}");
        let (lo, hi) = span(&|d| d.twist);
        assert!(lo < -60.0 && hi > 70.0, "twist {lo}..{hi}");
    }

    #[test]
    fn the_thumb_rests_in_front_of_the_palm() {
        // Where the palm faces, checked against the anatomy rather than the construction: at
        // rest the thumb's tip lies on the palm's side of the hand (centimetres from it).
        let body = Body::new();
        for (s, sx) in ["L", "R"].iter().enumerate() {
            let h = |n: &str| body.subject.heads[body.bone(&format!("{n}.{sx}"))];
            let off = (h("finger1-3") - h("wrist")).dot(body.rig.palm(s).unwrap());
            assert!(
                off > 0.2,
                "{sx}: the thumb's tip {off} dm from the wrist along the palm"
            );
        }
    }

    #[test]
    fn curled_fingers_close_towards_the_palm() {
        let body = Body::new();
        let rest = body.posed(&Angles::default());
        let curl = |c: f32| {
            body.posed(&Angles {
                finger_curl: both(c),
                ..Default::default()
            })
        };
        let (bent, fist) = (curl(40.0), curl(90.0));
        for (s, sx) in ["L", "R"].iter().enumerate() {
            let palm = body.rig.palm(s).unwrap();
            let wrist = body.head_m(&rest, &format!("wrist.{sx}"));
            for k in 2..=5 {
                let tip = format!("finger{k}-3.{sx}");
                let knuckle = body.head_m(&rest, &format!("finger{k}-1.{sx}"));
                let (a, b, f) = (
                    body.centroid(&rest, &tip),
                    body.centroid(&bent, &tip),
                    body.centroid(&fist, &tip),
                );
                // A bent finger's tip moves towards the palm (metres).
                assert!((b - a).dot(palm) > 0.015, "{tip}: {}", (b - a).dot(palm));
                // In a fist it lies on the palm's side of its knuckle, nearer the wrist.
                assert!(
                    (f - knuckle).dot(palm) > 0.0,
                    "{tip}: {}",
                    (f - knuckle).dot(palm)
                );
                let (da, df) = ((a - wrist).length(), (f - wrist).length());
                assert!(df < 0.8 * da, "{tip}: {da} -> {df} m from the wrist");
            }
        }
    }

    #[test]
    fn the_wrist_and_forearm_turn_the_named_ways() {
        let body = Body::new();
        let rest = body.posed(&Angles::default());
        let pose = |f: &dyn Fn(&mut Angles)| {
            let mut a = Angles::default();
            f(&mut a);
            body.posed(&a)
        };
        let flexed = pose(&|a| a.wrist_flex = both(50.0));
        let ulnar = pose(&|a| a.wrist_dev = both(25.0));
        let pronated = pose(&|a| a.forearm_twist = both(70.0));
        for (s, sx) in ["L", "R"].iter().enumerate() {
            let palm = body.rig.palm(s).unwrap();
            let h = |n: &str| body.subject.heads[body.bone(&format!("{n}.{sx}"))];
            let across = (h("finger5-1") - h("finger2-1")).normalize();
            let tip = format!("finger3-3.{sx}");
            let moved = |p: &Posed, n: &str| body.centroid(p, n) - body.centroid(&rest, n);
            // Flexion: the hand towards the palm.
            let d = moved(&flexed, &tip).dot(palm);
            assert!(d > 0.05, "{tip} flexion: {d} m");
            // Ulnar deviation: towards the little finger.
            let d = moved(&ulnar, &tip).dot(across);
            assert!(d > 0.03, "{tip} deviation: {d} m");
            // Pronation turns the palm to face backward: the thumb, in front of the palm at
            // rest, swings backward (-z) on either side.
            let thumb = format!("finger1-3.{sx}");
            let d = -moved(&pronated, &thumb).z;
            assert!(d > 0.03, "{thumb} pronation: {d} m backward");
        }
    }

    #[test]
    fn hand_poses_are_mirror_symmetric() {
        // A pose and its mirror image (sides swapped) put every hand bone's vertices at
        // mirrored places: the same angle turns the left and the right hand alike.
        let body = Body::new();
        let a = Angles {
            forearm_twist: [60.0, -30.0],
            wrist_flex: [40.0, -25.0],
            wrist_dev: [20.0, -10.0],
            finger_curl: [50.0, 80.0],
            ..Default::default()
        };
        let sw = |v: [f32; 2]| [v[1], v[0]];
        let m = Angles {
            forearm_twist: sw(a.forearm_twist),
            wrist_flex: sw(a.wrist_flex),
            wrist_dev: sw(a.wrist_dev),
            finger_curl: sw(a.finger_curl),
            ..a
        };
        let (pa, pm) = (body.posed(&a), body.posed(&m));
        for n in [
            "wrist",
            "finger1-3",
            "finger2-3",
            "finger3-3",
            "finger5-3",
            "lowerarm02",
        ] {
            for (s, o) in [("L", "R"), ("R", "L")] {
                let want = body.centroid(&pa, &format!("{n}.{s}"));
                let got = body.centroid(&pm, &format!("{n}.{o}"));
                let want = Vec3::new(-want.x, want.y, want.z);
                assert!(
                    (got - want).length() < 0.01,
                    "{n}.{s}: mirror {got} against {want}"
                );
            }
        }
    }
}
