//! The ladder a budget's ε is searched on: 512 steps evenly spaced in log ε, and the search for
//! the smallest step whose planes fit the budget (secant steps on log planes against log ε,
//! falling back to bisection when they stall).

/// ε (as a fraction of the radius) is searched for between these.
const BUDGET_EPSILON_RANGE: (f32, f32) = (0.002, 0.5);
/// The ε a budget may take: this many steps over the range, evenly spaced in log ε (each ε 1.08 %
/// above the one before).
pub const BUDGET_LADDER_STEPS: u32 = 512;

/// The ε (a fraction of the radius) of a step of the budget ladder.
pub fn ladder_epsilon(step: u32) -> f32 {
    let (low, high) = (BUDGET_EPSILON_RANGE.0.ln(), BUDGET_EPSILON_RANGE.1.ln());
    (low + (high - low) * step.min(BUDGET_LADDER_STEPS) as f32 / BUDGET_LADDER_STEPS as f32).exp()
}

/// What one probe of the ε search learned: whether the planes fit the cap at that step, and
/// about how many planes the step needs (exact when they fit; when they do not, an estimate
/// from below).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LadderProbe {
    pub fits: bool,
    pub planes: f32,
}

/// The smallest ladder step at which `probe` fits, assuming fitting is monotone (it fits from some
/// step on); `None` when even the last step does not fit. The plane count follows a power of ε
/// locally, so each probe goes where the line through the last two probes (log planes against
/// log ε; the first probe alone takes a slope of 1.5) meets log `cap`, then one step further
/// toward the side not yet seen, two, four… after probes that kept landing on the same side; a
/// probe that leaves more than half of the candidates of two probes before makes the next one a
/// bisection. On power laws this takes 4 probes on average (at most 8) where bisection takes 9
/// or 10, with the same answer wherever the count is monotone; on the corpus trees, whose counts
/// wobble by a few planes from step to step near the answer, 5 to 9.
///
/// A fitting probe with at least `enough` planes ends the search at once (infinity: the smallest
/// fitting step, always): a budget's planes are refined and filled up to the cap afterwards, so
/// a step whose greedy pass comes near the cap serves as well as the smallest.
pub fn search_epsilon_ladder(cap: f32, enough: f32, mut probe: impl FnMut(u32) -> LadderProbe) -> Option<u32> {
    let step_log = (BUDGET_EPSILON_RANGE.1 / BUDGET_EPSILON_RANGE.0).ln() / BUDGET_LADDER_STEPS as f32;
    // The highest step known not to fit and the lowest known to fit.
    let (mut highest_failing, mut lowest_fitting): (Option<u32>, Option<u32>) = (None, None);
    let mut probes: Vec<(u32, LadderProbe)> = Vec::new();
    let mut widths = vec![BUDGET_LADDER_STEPS + 1];
    let mut same_side = 0;
    let mut next = BUDGET_LADDER_STEPS / 2;
    loop {
        let result = probe(next);
        let result = LadderProbe { planes: result.planes.max(1.0), ..result };
        same_side = if probes.last().is_some_and(|(_, last)| last.fits == result.fits) { same_side + 1 } else { 0 };
        if result.fits {
            if result.planes >= enough {
                return Some(next);
            }
            lowest_fitting = Some(next);
        } else {
            highest_failing = Some(next);
        }
        let previous = probes.last().copied();
        probes.push((next, result));
        // The answer lies in first..=last (last = LADDER + 1: none fits).
        let first = highest_failing.map_or(0, |step| step + 1);
        let last = lowest_fitting.unwrap_or(BUDGET_LADDER_STEPS + 1);
        if first >= last {
            return (last <= BUDGET_LADDER_STEPS).then_some(last);
        }
        let highest_candidate = last - 1;
        widths.push(last - first);
        let stalled = 2 * widths[widths.len() - 1] > widths[widths.len().saturating_sub(3)];
        next = if stalled && widths.len() >= 3 {
            first + (highest_candidate - first) / 2
        } else {
            let slope = match previous {
                Some((step, earlier)) if step != next => ((earlier.planes.ln() - result.planes.ln())
                    / ((next as f32 - step as f32) * step_log))
                    .clamp(0.3, 6.0),
                _ => 1.5,
            };
            let root = next as f32 + (result.planes.ln() - cap.max(1.0).ln()) / (slope * step_log);
            let push = (1u32 << same_side.min(16)) as f32;
            let guess = if result.fits { root.floor() - push } else { root.ceil() + push };
            (guess.clamp(first as f32, highest_candidate as f32)) as u32
        };
    }
}
