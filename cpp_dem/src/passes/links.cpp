// The link pass: the geogrid's cohesive beams (000 eqs 7–12, laws/beam.hpp) and their breakage.
#include "cpp_dem/laws/beam.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
constexpr long kParallelMinGrid = 128;
}

void Scene::compute_links() {
  compute_links_hot();
  // Breakage events, in link order: the link is removed and the event recorded.
  const long nl = static_cast<long>(links_.size());
  for (long k = 0; k < nl; ++k) {
    GridLink& l = links_[k];
    if (l.broken || l.pending_break < 0) continue;
    BreakEvent ev;
    ev.step = step_;
    ev.time = time_;
    ev.link = static_cast<int>(k);
    ev.reason = l.pending_break;
    ev.force = l.pending_break == 0 ? l.fn : l.fs.norm();
    breaks_.push_back(ev);
    dropped_plastic_ += l.elastic_energy();
    l.broken = true;
    l.pending_break = -1;
    l.force_b.setZero();
    l.torque_a.setZero();
    l.torque_b.setZero();
  }
}

// (Multiversioned as the other hot passes, core/types.hpp: beam_link_step is inlined into
// each clone, whose IEEE operations are the baseline's, in its order: the same bits.)
void Scene::compute_links_hot() {
  const long nl = static_cast<long>(links_.size());
  const Real dt = dt_;
#pragma omp parallel for schedule(static) if (nl > kParallelMinGrid)
  for (long k = 0; k < nl; ++k) {
    GridLink& l = links_[k];
    if (l.broken) continue;
    beam_link_step(l, bodies_.pos[l.a], bodies_.pos[l.b], bodies_.vel[l.a], bodies_.vel[l.b],
                   bodies_.angvel[l.a], bodies_.angvel[l.b], dt);
  }
}

}  // namespace cpp_dem
