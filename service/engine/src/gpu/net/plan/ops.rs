//! Each ONNX op as kernels (or as a view, or folded at plan time when its inputs are
//! constants). The ONNX operator semantics followed are opset 13's; older attribute forms
//! (Slice, Unsqueeze, Squeeze, Pad, Clip taking attributes) are read too.

mod layers;

use super::{Attrs, Data, Kernel, Planner, Val, numel, pad6, strides};
pub(super) use layers::bilinear_x2;
use layers::{bn_affine, conv, gemm, pool, resize};
use tract_onnx::pb::NodeProto;

type Act = (u32, f32, f32);

/// Input `i` of node `n`, `None` when absent or empty (an omitted optional input).
fn input(n: &NodeProto, i: usize) -> Option<&str> {
    n.input.get(i).map(|s| s.as_str()).filter(|s| !s.is_empty())
}

fn axis(a: i64, rank: usize) -> Result<usize, String> {
    let r = rank as i64;
    let v = if a < 0 { a + r } else { a };
    if (0..r.max(1)).contains(&v) {
        Ok(v as usize)
    } else {
        Err(format!("axis {a} is outside rank {rank}"))
    }
}

/// Translate node `n` (its output named `out`: the last fused follower's); `act` is a fused
/// activation, `bn` a batch-norm folded into a Conv.
pub(super) fn node(
    pl: &mut Planner,
    n: &NodeProto,
    out: &str,
    act: Act,
    bn: Option<&NodeProto>,
) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let inp = |i: usize| input(n, i);
    let x = inp(0).unwrap_or("");
    match n.op_type.as_str() {
        "Constant" => {
            let (shape, data) = if let Some(t) = a.get("value").and_then(|v| v.t.as_ref()) {
                super::tensor_data(t).map_err(|e| pl.err(e))?
            } else if let Some(v) = a.get("value_float") {
                (vec![], Data::F(vec![v.f]))
            } else if let Some(v) = a.get("value_floats") {
                (vec![v.floats.len()], Data::F(v.floats.clone()))
            } else if let Some(v) = a.get("value_int") {
                (vec![], Data::I(vec![v.i]))
            } else if let Some(v) = a.get("value_ints") {
                (vec![v.ints.len()], Data::I(v.ints.clone()))
            } else {
                return Err(pl.err("Constant without a value this backend reads"));
            };
            pl.define_const(out, shape, data);
        }
        "Identity" => alias(pl, x, out, None)?,
        "Cast" => {
            let to = a.int("to", 1);
            match pl.get(x)?.clone() {
                Val::Const { shape, data } => {
                    let data = match to {
                        1 => Data::F(data.floats()),
                        6 | 7 => Data::I(data.ints()),
                        _ => return Err(pl.err(format!("Cast to type {to}"))),
                    };
                    pl.define_const(out, shape, data);
                }
                Val::Dev { .. } if to == 1 => alias(pl, x, out, None)?,
                Val::Dev { .. } => {
                    return Err(pl.err(format!("Cast of a device tensor to type {to}")));
                }
            }
        }
        "Shape" => {
            let s = pl.get(x)?.shape().to_vec();
            let r = s.len() as i64;
            let clampi = |v: i64| (if v < 0 { v + r } else { v }).clamp(0, r) as usize;
            let (b, e) = (clampi(a.int("start", 0)), clampi(a.int("end", r)));
            let dims: Vec<i64> = s[b..e.max(b)].iter().map(|&d| d as i64).collect();
            pl.define_const(out, vec![dims.len()], Data::I(dims));
        }
        "Gather" => {
            let (shape, data) = pl.konst(x)?;
            let (ishape, idx) = pl.konst(inp(1).unwrap_or(""))?;
            if shape.len() != 1 || a.int("axis", 0) != 0 {
                return Err(pl.err("Gather only of a 1-D constant (shape arithmetic)"));
            }
            let idx = idx.ints();
            let n0 = shape[0] as i64;
            let pick = |i: i64| -> Result<usize, String> {
                let j = if i < 0 { i + n0 } else { i };
                usize::try_from(j)
                    .ok()
                    .filter(|&j| j < shape[0])
                    .ok_or_else(|| pl.err(format!("index {i} outside {n0}")))
            };
            let data = match data {
                Data::F(v) => Data::F(
                    idx.iter()
                        .map(|&i| pick(i).map(|j| v[j]))
                        .collect::<Result<_, _>>()?,
                ),
                Data::I(v) => Data::I(
                    idx.iter()
                        .map(|&i| pick(i).map(|j| v[j]))
                        .collect::<Result<_, _>>()?,
                ),
            };
            pl.define_const(out, ishape, data);
        }
        "Reshape" => {
            let old = pl.get(x)?.shape().to_vec();
            let (_, spec) = pl.konst(inp(1).unwrap_or(""))?;
            let mut dims: Vec<i64> = spec.ints();
            for (d, v) in dims.iter_mut().enumerate() {
                if *v == 0 && a.int("allowzero", 0) == 0 {
                    *v = *old
                        .get(d)
                        .ok_or_else(|| pl.err("0 in the shape past the input's rank"))?
                        as i64;
                }
            }
            let known: i64 = dims.iter().filter(|&&v| v >= 0).product();
            let total = numel(&old) as i64;
            let shape: Vec<usize> = dims
                .iter()
                .map(|&v| {
                    if v < 0 {
                        (total / known.max(1)) as usize
                    } else {
                        v as usize
                    }
                })
                .collect();
            if numel(&shape) != numel(&old) {
                return Err(pl.err(format!("cannot reshape {old:?} to {dims:?}")));
            }
            alias(pl, x, out, Some(shape))?;
        }
        "Flatten" => {
            let old = pl.get(x)?.shape().to_vec();
            let k = axis(a.int("axis", 1), old.len() + 1).map_err(|e| pl.err(e))?;
            let shape = vec![numel(&old[..k]), numel(&old[k..])];
            alias(pl, x, out, Some(shape))?;
        }
        "Unsqueeze" | "Squeeze" => {
            let old = pl.get(x)?.shape().to_vec();
            let axes: Option<Vec<i64>> = match inp(1) {
                Some(name) => Some(pl.konst(name)?.1.ints()),
                None => a.ints("axes"),
            };
            let shape = if n.op_type == "Unsqueeze" {
                let axes = axes.ok_or_else(|| pl.err("Unsqueeze without axes"))?;
                let r = old.len() + axes.len();
                let mut ax: Vec<usize> = axes
                    .iter()
                    .map(|&v| axis(v, r))
                    .collect::<Result<_, _>>()
                    .map_err(|e| pl.err(e))?;
                ax.sort();
                let mut s = old.clone();
                for v in ax {
                    s.insert(v, 1);
                }
                s
            } else {
                let ax: Vec<usize> = match axes {
                    Some(v) => v
                        .iter()
                        .map(|&v| axis(v, old.len()))
                        .collect::<Result<_, _>>()
                        .map_err(|e| pl.err(e))?,
                    None => (0..old.len()).filter(|&d| old[d] == 1).collect(),
                };
                old.iter()
                    .enumerate()
                    .filter(|(d, _)| !ax.contains(d))
                    .map(|(_, &v)| v)
                    .collect()
            };
            alias(pl, x, out, Some(shape))?;
        }
        "Concat" => concat(pl, n, out, a.int("axis", 0))?,
        "Slice" => slice(pl, n, out)?,
        "Transpose" => {
            let (buf, shape) = pl.dev(x)?;
            let perm: Vec<usize> = match a.ints("perm") {
                Some(p) => p
                    .iter()
                    .map(|&v| axis(v, shape.len()))
                    .collect::<Result<_, _>>()
                    .map_err(|e| pl.err(e))?,
                None => (0..shape.len()).rev().collect(),
            };
            let st = strides(&shape);
            let oshape: Vec<usize> = perm.iter().map(|&p| shape[p]).collect();
            let ist: Vec<i64> = perm.iter().map(|&p| st[p] as i64).collect();
            let o = pl.alloc(numel(&oshape));
            pl.copy(buf, 0, &ist, o, 0, &strides(&oshape), &oshape);
            pl.define_dev(out, o, oshape);
        }
        "Pad" => pad(pl, n, out)?,
        "Add" | "Sub" | "Mul" | "Div" | "Max" | "Min" => {
            if n.input.len() != 2 {
                return Err(pl.err(format!(
                    "{} of {} inputs (2 run on the GPU)",
                    n.op_type,
                    n.input.len()
                )));
            }
            let op = ["Add", "Sub", "Mul", "Div", "Max", "Min"]
                .iter()
                .position(|o| *o == n.op_type)
                .unwrap_or(0) as u32;
            binary(pl, op, x, inp(1).unwrap_or(""), out)?;
        }
        "Relu" | "LeakyRelu" | "HardSwish" | "Sigmoid" | "Tanh" | "HardSigmoid" | "Clip" => {
            let (op, p1, p2) = if n.op_type == "Clip" {
                let lo = match inp(1) {
                    Some(m) => pl.konst(m)?.1.floats().first().copied().unwrap_or(f32::MIN),
                    None => a.float("min", f32::MIN),
                };
                let hi = match inp(2) {
                    Some(m) => pl.konst(m)?.1.floats().first().copied().unwrap_or(f32::MAX),
                    None => a.float("max", f32::MAX),
                };
                (6, lo, hi)
            } else {
                super::activation(n).unwrap_or((0, 0.0, 0.0))
            };
            let (buf, shape) = pl.dev(x)?;
            let o = pl.alloc(numel(&shape));
            let c = numel(&shape) as u32;
            pl.step(
                Kernel::Unary,
                vec![c, op, p1.to_bits(), p2.to_bits()],
                vec![buf, o],
            );
            pl.define_dev(out, o, shape);
        }
        "Conv" | "ConvTranspose" => conv(pl, n, out, act, bn)?,
        "AveragePool" | "MaxPool" | "GlobalAveragePool" | "GlobalMaxPool" => pool(pl, n, out)?,
        "Gemm" | "MatMul" => gemm(pl, n, out, act)?,
        "Resize" => resize(pl, n, out)?,
        "BatchNormalization" => {
            let (scale, shift) = bn_affine(pl, n)?;
            let c = scale.len();
            // The channel axis is 1: [C] then a unit axis per spatial axis.
            let rank = pl.get(x)?.shape().len();
            let cshape: Vec<usize> = std::iter::once(c)
                .chain(std::iter::repeat_n(1, rank.saturating_sub(2)))
                .collect();
            let tmp = format!("{out}#scaled");
            let sname = format!("{out}#bn_scale");
            let bname = format!("{out}#bn_shift");
            pl.define_const(&sname, cshape.clone(), Data::F(scale));
            pl.define_const(&bname, cshape, Data::F(shift));
            pl.uses.insert(tmp.clone(), 1);
            binary(pl, 2, x, &sname, &tmp)?;
            binary(pl, 0, &tmp, &bname, out)?;
            pl.release(&tmp);
        }
        other => return Err(pl.err(format!("op {other} has no GPU kernel"))),
    }
    Ok(())
}

/// `out` is `x` (reshaped to `shape` when given): the same buffer, no kernel.
fn alias(pl: &mut Planner, x: &str, out: &str, shape: Option<Vec<usize>>) -> Result<(), String> {
    match pl.get(x)?.clone() {
        Val::Const { shape: s, data } => {
            pl.define_const(out, shape.unwrap_or(s), data);
        }
        Val::Dev { buf, shape: s } => pl.define_dev(out, buf, shape.unwrap_or(s)),
    }
    Ok(())
}

/// NumPy broadcasting of two shapes: the output shape and each input's strides in it.
fn broadcast(a: &[usize], b: &[usize]) -> Option<(Vec<usize>, Vec<i64>, Vec<i64>)> {
    let r = a.len().max(b.len());
    let pad = |s: &[usize]| -> Vec<usize> {
        std::iter::repeat_n(1, r - s.len())
            .chain(s.iter().copied())
            .collect()
    };
    let (pa, pb) = (pad(a), pad(b));
    let mut out = Vec::with_capacity(r);
    for d in 0..r {
        let (x, y) = (pa[d], pb[d]);
        out.push(if x == y || y == 1 {
            x
        } else if x == 1 {
            y
        } else {
            return None;
        });
    }
    let st = |p: &[usize]| -> Vec<i64> {
        let s = strides(p);
        (0..r)
            .map(|d| {
                if p[d] == 1 && out[d] != 1 {
                    0
                } else {
                    s[d] as i64
                }
            })
            .collect()
    };
    Some((out.clone(), st(&pa), st(&pb)))
}

fn binary(pl: &mut Planner, op: u32, x: &str, y: &str, out: &str) -> Result<(), String> {
    let (sa, sb) = (pl.get(x)?.shape().to_vec(), pl.get(y)?.shape().to_vec());
    let (oshape, ast, bst) = broadcast(&sa, &sb)
        .ok_or_else(|| pl.err(format!("shapes {sa:?} and {sb:?} do not broadcast")))?;
    if oshape.len() > super::MAX_RANK {
        return Err(pl.err(format!(
            "rank {} (at most {})",
            oshape.len(),
            super::MAX_RANK
        )));
    }
    // Both constant: fold on the host (shape arithmetic).
    if let (Val::Const { data: da, .. }, Val::Const { data: db, .. }) =
        (pl.get(x)?.clone(), pl.get(y)?.clone())
    {
        let n = numel(&oshape);
        let st = strides(&oshape);
        let at = |s: &[i64], i: usize| -> usize {
            (0..oshape.len())
                .map(|d| (i / st[d]) % oshape[d] * s[d] as usize)
                .sum()
        };
        let ints = matches!((&da, &db), (Data::I(_), Data::I(_)));
        let (fa, fb, ia, ib) = (da.floats(), db.floats(), da.ints(), db.ints());
        let data = if ints {
            Data::I(
                (0..n)
                    .map(|i| {
                        let (u, v) = (ia[at(&ast, i)], ib[at(&bst, i)]);
                        match op {
                            0 => u + v,
                            1 => u - v,
                            2 => u * v,
                            3 => {
                                if v != 0 {
                                    u / v
                                } else {
                                    0
                                }
                            }
                            4 => u.max(v),
                            _ => u.min(v),
                        }
                    })
                    .collect(),
            )
        } else {
            Data::F(
                (0..n)
                    .map(|i| {
                        let (u, v) = (fa[at(&ast, i)], fb[at(&bst, i)]);
                        match op {
                            0 => u + v,
                            1 => u - v,
                            2 => u * v,
                            3 => u / v,
                            4 => u.max(v),
                            _ => u.min(v),
                        }
                    })
                    .collect(),
            )
        };
        pl.define_const(out, oshape, data);
        return Ok(());
    }
    let (ba, _) = pl.dev(x)?;
    let (bb, _) = pl.dev(y)?;
    let o = pl.alloc(numel(&oshape));
    let (sh, ast) = pad6(&oshape, &ast);
    let (_, bst) = pad6(&oshape, &bst);
    let mut p = vec![numel(&oshape) as u32, op];
    p.extend(sh);
    p.extend(ast);
    p.extend(bst);
    pl.step(Kernel::Binary, p, vec![ba, bb, o]);
    pl.define_dev(out, o, oshape);
    Ok(())
}

fn concat(pl: &mut Planner, n: &NodeProto, out: &str, ax: i64) -> Result<(), String> {
    let names: Vec<&str> = n
        .input
        .iter()
        .map(|s| s.as_str())
        .filter(|s| !s.is_empty())
        .collect();
    let first = pl
        .get(names.first().copied().unwrap_or(""))?
        .shape()
        .to_vec();
    let k = axis(ax, first.len()).map_err(|e| pl.err(e))?;
    let mut oshape = first.clone();
    oshape[k] = 0;
    for name in &names {
        let s = pl.get(name)?.shape().to_vec();
        if s.len() != first.len() || (0..s.len()).any(|d| d != k && s[d] != first[d]) {
            return Err(pl.err(format!("Concat of {first:?} and {s:?} along axis {k}")));
        }
        oshape[k] += s[k];
    }
    let all_const = names
        .iter()
        .all(|m| matches!(pl.vals.get(*m), Some(Val::Const { .. })));
    if all_const && first.len() == 1 {
        let parts: Vec<Data> = names
            .iter()
            .map(|m| pl.konst(m).map(|c| c.1))
            .collect::<Result<_, _>>()?;
        let data = if parts.iter().all(|d| matches!(d, Data::I(_))) {
            Data::I(parts.iter().flat_map(|d| d.ints()).collect())
        } else {
            Data::F(parts.iter().flat_map(|d| d.floats()).collect())
        };
        pl.define_const(out, oshape, data);
        return Ok(());
    }
    let o = pl.alloc(numel(&oshape));
    let ost = strides(&oshape);
    let mut at = 0;
    for name in names {
        let (b, s) = pl.dev(name)?;
        let ist: Vec<i64> = strides(&s).iter().map(|&v| v as i64).collect();
        pl.copy(b, 0, &ist, o, at * ost[k], &ost, &s);
        at += s[k];
    }
    pl.define_dev(out, o, oshape);
    Ok(())
}

fn slice(pl: &mut Planner, n: &NodeProto, out: &str) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let x = n.input.first().map(|s| s.as_str()).unwrap_or("");
    let shape = pl.get(x)?.shape().to_vec();
    let r = shape.len();
    let inp = |i: usize| input(n, i);
    let get = |pl: &Planner, i: usize, attr: &str| -> Result<Option<Vec<i64>>, String> {
        match inp(i) {
            Some(name) => Ok(Some(pl.konst(name)?.1.ints())),
            None => Ok(a.ints(attr)),
        }
    };
    let starts = get(pl, 1, "starts")?.ok_or_else(|| pl.err("Slice without starts"))?;
    let ends = get(pl, 2, "ends")?.ok_or_else(|| pl.err("Slice without ends"))?;
    let axes = get(pl, 3, "axes")?.unwrap_or_else(|| (0..starts.len() as i64).collect());
    let steps = get(pl, 4, "steps")?.unwrap_or_else(|| vec![1; starts.len()]);
    let mut begin = vec![0i64; r];
    let mut step = vec![1i64; r];
    let mut oshape = shape.clone();
    for (j, &ax) in axes.iter().enumerate() {
        let d = axis(ax, r).map_err(|e| pl.err(e))?;
        let dim = shape[d] as i64;
        let st = steps.get(j).copied().unwrap_or(1);
        if st == 0 {
            return Err(pl.err("Slice step 0"));
        }
        let fix = |v: i64, lo: i64, hi: i64| (if v < 0 { v + dim } else { v }).clamp(lo, hi);
        let (b, e) = if st > 0 {
            (fix(starts[j], 0, dim), fix(ends[j], 0, dim))
        } else {
            (fix(starts[j], -1, dim - 1), fix(ends[j], -1, dim - 1))
        };
        let len = if st > 0 {
            (e - b + st - 1).div_euclid(st)
        } else {
            (b - e + (-st) - 1).div_euclid(-st)
        };
        oshape[d] = len.max(0) as usize;
        begin[d] = b;
        step[d] = st;
    }
    let ist0 = strides(&shape);
    let off: i64 = (0..r).map(|d| begin[d] * ist0[d] as i64).sum();
    let ist: Vec<i64> = (0..r).map(|d| step[d] * ist0[d] as i64).collect();
    if let Val::Const { data, .. } = pl.get(x)?.clone() {
        let ost = strides(&oshape);
        let idx = |i: usize| -> usize {
            (off + (0..r)
                .map(|d| ((i / ost[d]) % oshape[d]) as i64 * ist[d])
                .sum::<i64>()) as usize
        };
        let m = numel(&oshape);
        let data = match data {
            Data::F(v) => Data::F((0..m).map(|i| v[idx(i)]).collect()),
            Data::I(v) => Data::I((0..m).map(|i| v[idx(i)]).collect()),
        };
        pl.define_const(out, oshape, data);
        return Ok(());
    }
    let (b, _) = pl.dev(x)?;
    let o = pl.alloc(numel(&oshape));
    pl.copy(b, off, &ist, o, 0, &strides(&oshape), &oshape);
    pl.define_dev(out, o, oshape);
    Ok(())
}

fn pad(pl: &mut Planner, n: &NodeProto, out: &str) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let mode = a.string("mode", "constant");
    if mode != "constant" {
        return Err(pl.err(format!("Pad mode {mode:?} (constant runs on the GPU)")));
    }
    let inp = |i: usize| input(n, i);
    let x = inp(0).unwrap_or("");
    let pads = match inp(1) {
        Some(p) => pl.konst(p)?.1.ints(),
        None => a.ints("pads").unwrap_or_default(),
    };
    let value = match inp(2) {
        Some(v) => pl.konst(v)?.1.floats().first().copied().unwrap_or(0.0),
        None => a.float("value", 0.0),
    };
    let (b, shape) = pl.dev(x)?;
    let r = shape.len();
    if pads.len() != 2 * r || pads.iter().any(|&p| p < 0) || inp(3).is_some() {
        return Err(pl.err(format!(
            "pads {pads:?} for rank {r} (non-negative, every axis)"
        )));
    }
    let oshape: Vec<usize> = (0..r)
        .map(|d| shape[d] + (pads[d] + pads[r + d]) as usize)
        .collect();
    let o = pl.alloc(numel(&oshape));
    pl.step(
        Kernel::Fill,
        vec![numel(&oshape) as u32, value.to_bits()],
        vec![o],
    );
    let ost = strides(&oshape);
    let off: usize = (0..r).map(|d| pads[d] as usize * ost[d]).sum();
    let ist: Vec<i64> = strides(&shape).iter().map(|&v| v as i64).collect();
    pl.copy(b, 0, &ist, o, off, &ost, &shape);
    pl.define_dev(out, o, oshape);
    Ok(())
}
