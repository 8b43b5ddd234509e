//! A bounding-volume hierarchy over primitives: median split on the longest
//! centroid axis, flattened depth-first, leaves of at most [`LEAF_SIZE`].
//! Ray casts visit the nearer child first and prune by the best hit so far;
//! distance queries prune by box distance.

use nalgebra::Point3;

use super::{Aabb, Primitive, PrimitiveHit, Ray};

const LEAF_SIZE: usize = 4;
const STACK: usize = 64;

#[derive(Debug, Clone)]
struct Node {
    bounds: Aabb,
    /// Leaf: first primitive; inner: index of the right child (the left
    /// child follows the node directly).
    first: u32,
    /// Number of primitives; 0 for an inner node.
    count: u32,
}

/// The acceleration structure of a [`super::Scene`].
#[derive(Debug, Clone)]
pub struct Bvh {
    nodes: Vec<Node>,
    primitives: Vec<Primitive>,
    objects: Vec<usize>,
}

impl Bvh {
    /// Builds the hierarchy over `(primitive, object index)` pairs.
    pub fn build(items: Vec<(Primitive, usize)>) -> Self {
        let mut items: Vec<(Primitive, usize, Aabb, Point3<f64>)> = items
            .into_iter()
            .map(|(p, o)| {
                let b = p.bounds();
                (p, o, b, b.center())
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * items.len() / LEAF_SIZE + 1);
        if !items.is_empty() {
            build_node(&mut items, 0, &mut nodes);
        }
        let (primitives, objects) = items.into_iter().map(|(p, o, _, _)| (p, o)).unzip();
        Self { nodes, primitives, objects }
    }

    /// Number of primitives.
    pub fn len(&self) -> usize {
        self.primitives.len()
    }

    /// Every primitive with its object index (in the hierarchy's order).
    pub fn primitives(&self) -> impl Iterator<Item = (&Primitive, usize)> + '_ {
        self.primitives.iter().zip(self.objects.iter().copied())
    }

    /// True when there are no primitives.
    pub fn is_empty(&self) -> bool {
        self.primitives.is_empty()
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bounding box of everything.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or_else(Aabb::empty, |n| n.bounds)
    }

    /// Nearest hit in `(t_min, t_max)` with its object index.
    pub fn cast(&self, ray: &Ray, t_min: f64, mut t_max: f64) -> Option<(PrimitiveHit, usize)> {
        let mut best = None;
        let mut stack = [0u32; STACK];
        let mut top = 0usize;
        self.nodes.first()?.bounds.hit(ray, t_min, t_max)?;
        let mut node = 0usize;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                let first = n.first as usize;
                for i in first..first + n.count as usize {
                    if let Some(h) = self.primitives[i].intersect(ray, t_min, t_max) {
                        t_max = h.distance_m;
                        best = Some((h, self.objects[i]));
                    }
                }
            } else {
                let (l, r) = (node + 1, n.first as usize);
                let hl = self.nodes[l].bounds.hit(ray, t_min, t_max);
                let hr = self.nodes[r].bounds.hit(ray, t_min, t_max);
                match (hl, hr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b { (l, r) } else { (r, l) };
                        // A median split halves every level, so the depth (and
                        // the stack) never exceeds log2(len) < STACK.
                        stack[top] = far as u32;
                        top += 1;
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            if top == 0 {
                return best;
            }
            top -= 1;
            node = stack[top] as usize;
        }
    }

    /// Distance from `p` to the nearest primitive, with its object index
    /// (`(∞, 0)` for an empty hierarchy).
    pub fn distance(&self, p: &Point3<f64>) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0);
        if self.nodes.is_empty() {
            return best;
        }
        let mut stack = vec![0usize];
        while let Some(node) = stack.pop() {
            let n = &self.nodes[node];
            if n.bounds.distance(p) >= best.0 {
                continue;
            }
            if n.count > 0 {
                let first = n.first as usize;
                for i in first..first + n.count as usize {
                    let d = self.primitives[i].distance(p);
                    if d < best.0 {
                        best = (d, self.objects[i]);
                    }
                }
            } else {
                let (l, r) = (node + 1, n.first as usize);
                let (dl, dr) = (self.nodes[l].bounds.distance(p), self.nodes[r].bounds.distance(p));
                if dl <= dr {
                    stack.extend([r, l]);
                } else {
                    stack.extend([l, r]);
                }
            }
        }
        best
    }
}

/// Builds the subtree for `items` (whose first primitive index is `offset`)
/// and returns its node index.
fn build_node(items: &mut [(Primitive, usize, Aabb, Point3<f64>)], offset: usize, nodes: &mut Vec<Node>) -> usize {
    let bounds = items.iter().fold(Aabb::empty(), |b, it| b.union(&it.2));
    let index = nodes.len();
    nodes.push(Node { bounds, first: offset as u32, count: items.len() as u32 });
    if items.len() <= LEAF_SIZE {
        return index;
    }
    let centroids = items.iter().fold(Aabb::empty(), |b, it| b.grown(&it.3));
    let extent = centroids.extent();
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| a.3[axis].total_cmp(&b.3[axis]));
    let (left, right) = items.split_at_mut(mid);
    build_node(left, offset, nodes);
    let r = build_node(right, offset + mid, nodes);
    nodes[index].first = r as u32;
    nodes[index].count = 0;
    index
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The BVH gives exactly the brute-force nearest hit and distance.
    #[test]
    fn matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut pt = |s: f64| Point3::new(rng.random_range(-s..s), rng.random_range(-s..s), rng.random_range(-s..s));
        let mut items = Vec::new();
        for i in 0..300 {
            let c = pt(10.0);
            let prim = match i % 3 {
                0 => Primitive::Triangle([c, c + pt(1.0).coords, c + pt(1.0).coords]),
                1 => Primitive::Sphere { center: c, radius_m: 0.3 },
                _ => Primitive::Cylinder { a: c, b: c + pt(2.0).coords, radius_m: 0.2 },
            };
            items.push((prim, i));
        }
        let bvh = Bvh::build(items.clone());
        assert_eq!(bvh.len(), 300);
        for _ in 0..500 {
            let o = pt(12.0);
            let ray = Ray::new(o, Vector3::new(pt(1.0).x, pt(1.0).y, pt(1.0).z)).expect("ray");
            let brute = items
                .iter()
                .filter_map(|(p, i)| p.intersect(&ray, 0.0, f64::INFINITY).map(|h| (h.distance_m, *i)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let fast = bvh.cast(&ray, 0.0, f64::INFINITY).map(|(h, i)| (h.distance_m, i));
            assert_eq!(brute, fast);
            let q = pt(12.0);
            let brute_d = items.iter().map(|(p, _)| p.distance(&q)).fold(f64::INFINITY, f64::min);
            assert_eq!(bvh.distance(&q).0, brute_d);
        }
    }
}
