//! ICP's settings: the error metric, the robust kernel and the flat
//! configuration struct with its documented defaults.

use nalgebra::Point3;

/// The error metric.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Point-to-point, closed form (Horn's unit quaternion).
    PointToPoint,
    /// Point-to-plane, Gauss–Newton on the target's normals.
    PointToPlane,
}

/// ICP settings (one flat struct, documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpConfig {
    /// Error metric. Default point-to-plane.
    pub method: Method,
    /// Pairs farther apart than this are ignored, metres. Default 1.0.
    pub max_correspondence_m: f64,
    /// Iteration cap. Default 50.
    pub max_iterations: usize,
    /// Converged when an update moves less than this, metres. Default 1e-5.
    pub translation_tolerance_m: f64,
    /// Converged when an update turns less than this, radians. Default 1e-5.
    pub rotation_tolerance_rad: f64,
    /// Neighbours for normal estimation. Default 10.
    pub normal_neighbours: usize,
    /// Robust kernel on the residuals. Default none (least squares).
    pub kernel: Kernel,
    /// Keep the estimate after every iteration in [`IcpResult::trace`](super::IcpResult::trace)
    /// (for viewing the registration). Default false.
    pub trace: bool,
    /// Leave out a pair whose target normal faces away from the source
    /// scanner ([`source_viewpoint`](Self::source_viewpoint)): the source
    /// cannot have seen that side of the surface, so the pair joins two
    /// faces of a thin object (a door reveal, a pilaster), which pulls a
    /// moving scanner back towards where it came from. Needs a target with
    /// oriented normals ([`Target::orient_normals_towards`](super::Target::orient_normals_towards)). Default false.
    pub reject_back_faces: bool,
    /// Where the source's scanner stands in the source frame, for
    /// `reject_back_faces` (a scan kept in a robot's body frame has its
    /// scanner at the head's lever arm). Default the origin.
    pub source_viewpoint: Point3<f64>,
    /// Point-to-plane: leave the directions the matches cannot see where
    /// the estimate (or the prior) holds them — a direction is unobservable
    /// when its eigenvalue of the normal matrix, rotation scaled by the
    /// source's RMS radius, is below this ratio of the largest
    /// ([`super::degeneracy`]); they are reported in
    /// [`IcpResult::unobservable`](super::IcpResult::unobservable). Default
    /// none: a singular normal matrix is an error.
    pub degeneracy_ratio: Option<f64>,
    /// Point-to-plane with `degeneracy_ratio`: judge the blind directions
    /// without the pairs whose partner's normal is not a surface's — its
    /// neighbourhood one scan line, the middle PCA eigenvalue below this
    /// ratio of its largest, or with no clear smallest direction
    /// ([`Target::middle_shares`](super::Target::middle_shares),
    /// [`AMBIGUOUS_NORMAL`](super::target::AMBIGUOUS_NORMAL)), and a wider
    /// neighbourhood a surface with another normal — since PCA takes a
    /// line's arc for the surface and gives it the line's own plane as
    /// normal, and two alike small eigenvalues any direction between them
    /// ([`Observability::judged`](super::Observability::judged)); a thin
    /// real structure (a pole, a wire) and a ring on flat ground keep
    /// theirs.
    /// Sparse scan lines of a pipe made its axis look seen both ways (the
    /// sewer at 60 slices: `match` at its last stage's 8.6 mm cells through
    /// the lines, `fuse --mode icp` at 0.1 m cells through the unclear
    /// normals; BENCHMARKS.md, "Sparse scan lines"); 0.1 holds it. The
    /// pairs stay in the solve. Default none.
    pub line_ratio: Option<f64>,
    /// Point-to-plane: leave out a pair whose source point lies beyond the
    /// part of the surface the target sampled around its partner — where a
    /// partial overlap ends, at an occlusion — matched to the last sample
    /// at the edge: its residual is the edge's, and all such pairs lean the
    /// same way. Default false.
    pub only_covered: bool,
    /// Point-to-plane, without `only_covered`: measure how far the pairs
    /// beyond the target's sampled edge pull the estimate — where the fit
    /// without them would step from it, linearised at the last pass
    /// ([`IcpResult::edge_bias`](super::IcpResult::edge_bias)), and
    /// without the covered pairs nearest the edge too
    /// ([`IcpResult::edge_lean`](super::IcpResult::edge_lean): one more
    /// pass over the last pass's pairs). It changes nothing of the match.
    /// Default false.
    pub edge_bias: bool,
    /// Point-to-plane: also report the estimate's covariance with each
    /// pair's variance its own squared residual (the sandwich H⁻¹·B·H⁻¹,
    /// B = Σ (w·r)²·JJᵀ) instead of one variance for all pairs — on real
    /// scans far points, which carry the rotation, are noisier, and so are
    /// some surfaces beside others at the same range
    /// ([`IcpResult::range_covariance`](super::IcpResult::range_covariance);
    /// the name is that of its first model, the variance by range bins).
    /// Nothing else changes. Default false.
    pub range_noise: bool,
    /// Point-to-plane, in a match both ways (the source's points also
    /// into the target's, on the source's normals): leave out a pair whose two
    /// points' own normals — the source point's, turned into the target's
    /// frame, and its partner's — meet at a cosine below this (|cos|: the
    /// normals' sides do not count). Where one scan samples a surface far
    /// more sparsely than the other — a façade seen at grazing angles in a
    /// rotating scanner's slices 2 m apart — its points' neighbourhoods are
    /// lines, and PCA gives them the plane across the surface: the other
    /// scan's points pair with them off that plane, and which of them pair
    /// with which changes with the scans' sampling as they slide, so the
    /// cost bumps every few decimetres along the surface and the coarse
    /// stages drag the scans there (BENCHMARKS.md, "Agreeing no better than
    /// the starts"). Both scans sample a surface alike when their normals
    /// agree. A one-way match (no source normals) is not affected.
    /// Default none.
    pub normal_agreement_cos: Option<f64>,
    /// Point-to-plane: leave out each pair whose target normal came from a
    /// neighbourhood that is not one plane — its smallest PCA eigenvalue
    /// above this share of its middle one: a corner or an edge where two
    /// surfaces meet among the normal's nearest points, whose PCA plane
    /// stands between them. Such neighbourhoods are not alike on both
    /// sides of a surface a scanner sees: the floor or ceiling near a wall
    /// is seen only in front of it, so the wall's points tilt those
    /// normals towards the scanner (on a simulated hall's scans, the
    /// floor's by 25–130 mrad on average 4–13 m out, 6–28 % of them by
    /// more than 0.1 rad), every match leans on its target scan's tilted
    /// normals alike, and a chain of scans bends (BENCHMARKS.md, "Normals
    /// at corners"). A target whose normals were given keeps every pair
    /// unless their corner shares came with them
    /// ([`Target::with_corner_shares`](super::Target::with_corner_shares)).
    /// Default none.
    pub corner_ratio: Option<f64>,
    /// With [`corner_ratio`](Self::corner_ratio): judge every target
    /// point's neighbourhood. Off (the default), only those whose ten
    /// nearest other points reach farther than `max_correspondence_m` —
    /// where the scan is sparse: far from its scanner, the neighbourhood
    /// spans two surfaces over decimetres and its normal leans most (a
    /// hall's floor by 25–230 mrad 4–18 m out), while near the scanner
    /// the lean is a few mrad and the corners are much of what holds a
    /// small room's scans along its walls (BENCHMARKS.md, "Corners where
    /// the scan is sparse").
    pub corner_everywhere: bool,
    /// Point-to-plane: what the residuals' own scatter misjudges of the
    /// estimate's variance, as a factor on the reported covariance —
    /// measured on the data by [`crate::noise::calibrate`] (random halves
    /// of each scan, matched where the truth is known). It scales only
    /// [`IcpResult::information`](super::IcpResult::information), never the
    /// iteration. Default 1.
    pub noise_scale: f64,
}

/// A robust kernel, applied by iteratively reweighted least squares: each
/// pair's weight is recomputed from its residual every iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kernel {
    /// Plain least squares (weight 1).
    None,
    /// Huber: weight 1 up to `width_m`, `width_m / |r|` beyond.
    Huber {
        /// The kernel width, metres.
        width_m: f64,
    },
}

impl Kernel {
    /// The IRLS weight of a residual (metres).
    pub(crate) fn weight(self, residual: f64) -> f64 {
        match self {
            Kernel::None => 1.0,
            Kernel::Huber { width_m } => {
                let a = residual.abs();
                if a <= width_m { 1.0 } else { width_m / a }
            }
        }
    }
}

impl IcpConfig {
    /// How far a target point's ten nearest other points must reach for
    /// the corner test to judge it, metres: the correspondence distance,
    /// or 0 (every point) with [`corner_everywhere`](Self::corner_everywhere).
    pub(crate) fn corner_reach_m(&self) -> f64 {
        if self.corner_everywhere { 0.0 } else { self.max_correspondence_m }
    }
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            method: Method::PointToPlane,
            max_correspondence_m: 1.0,
            max_iterations: 50,
            translation_tolerance_m: 1e-5,
            rotation_tolerance_rad: 1e-5,
            normal_neighbours: 10,
            kernel: Kernel::None,
            trace: false,
            reject_back_faces: false,
            source_viewpoint: Point3::origin(),
            degeneracy_ratio: None,
            line_ratio: None,
            only_covered: false,
            edge_bias: false,
            range_noise: false,
            normal_agreement_cos: None,
            corner_ratio: None,
            corner_everywhere: false,
            noise_scale: 1.0,
        }
    }
}
