// Pinocchio's constrained forward dynamics of a spatial leg, timed: the benchmarks' C++
// peer for spatial legs (`cargo xtask bench --pinocchio` builds and runs it; not part of
// CI). The model is Pinocchio's own URDF parser's reading of `cargo xtask export NAME
// --format urdf` (a ball joint as three revolute joints, so its coordinates are ours); the
// closures are 3-D point constraints between the frames `<closure>.a` and `<closure>.b`,
// as a Pinocchio user writes loop closures.
//
// A floating robot (a `free` line) is read with a `JointModelFreeFlyer` root, Pinocchio's
// own free joint (one 6-dof joint, not six 1-dof ones): its URDF is `cargo xtask bench`'s
// with the body as the root link (export::spatial::urdf_floating). Its held contact points
// (`contact` lines) make a second call timed: the closures and every contact point held in
// the world (CONTACT_3D between the frame `<contact>.point` and the universe), a stance.
//
// usage: pinocchio_spatial_bench URDF STATE_FILE
//
// STATE_FILE, one item per line: `gravity gx gy gz`; `joint NAME` per coordinate in our
// order (a floating robot's six free-joint coordinates left out); `free F px py pz qw qx
// qy qz`: our coordinates F … F+5 are the body's free joint, at the pose given (position,
// unit quaternion); `armature NAME VALUE`; `closure NAME`; `contact NAME`; `q …`, `v …`,
// `tau …` in our order (tau is the generalized force B u − D q̇ − the springs' ∂V/∂q:
// Pinocchio models neither damping nor springs, so its call does those few products less
// than ours). The free joint's six `q` must be zero (our chart centred on the body) and its
// six `v` are then the body's linear and angular velocity in its own frame, which is
// Pinocchio's free-flyer velocity; its q̈ is Pinocchio's v̇, the derivative of those
// body-frame components (ours: leg_models::robot::velocity_derivative of the chart's q̈).
//
// One call = `constraintDynamics` with ProximalSettings(accuracy 1e-12, μ 1e-8, at most
// 100 iterations): converged, it is the exact constrained solution, redundant rows
// included. It is also timed at one proximal iteration (Pinocchio's fastest setting; its q̈
// is then the regularized one). Prints one JSON object: qdd (ours order, converged),
// iterations (the converged solve's), median_ns, one_iteration_qdd, one_iteration_ns,
// fewest_qdd, fewest_iterations, fewest_ns (the fewest iterations that give the converged
// q̈, to 1e-10 relative), and with contacts the same of the stance: stance_qdd,
// stance_iterations, stance_median_ns, stance_fewest_qdd, stance_fewest_iterations,
// stance_fewest_ns.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/frames.hpp>

namespace pin = pinocchio;

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: pinocchio_spatial_bench URDF STATE_FILE\n");
    return 2;
  }
  std::ifstream in(argv[2]);
  if (!in) {
    std::fprintf(stderr, "%s: cannot read\n", argv[2]);
    return 1;
  }
  std::vector<std::string> joints, closures, contacts;
  std::vector<std::pair<std::string, double>> armatures;
  std::vector<double> q_ours, v_ours, tau_ours, pose;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  int free = -1;  // our free joint's first coordinate, or none
  std::string line;
  auto numbers = [](std::istringstream& s) {
    std::vector<double> v;
    double x;
    while (s >> x) v.push_back(x);
    return v;
  };
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key == "gravity") {
      s >> gravity(0) >> gravity(1) >> gravity(2);
    } else if (key == "free") {
      s >> free;
      pose = numbers(s);
    } else if (key == "joint") {
      std::string n;
      s >> n;
      joints.push_back(n);
    } else if (key == "armature") {
      std::string n;
      double a;
      s >> n >> a;
      armatures.emplace_back(n, a);
    } else if (key == "closure") {
      std::string n;
      s >> n;
      closures.push_back(n);
    } else if (key == "contact") {
      std::string n;
      s >> n;
      contacts.push_back(n);
    } else if (key == "q") {
      q_ours = numbers(s);
    } else if (key == "v") {
      v_ours = numbers(s);
    } else if (key == "tau") {
      tau_ours = numbers(s);
    }
  }
  pin::Model model;
  if (free >= 0) {
    if (pose.size() != 7) {
      std::fprintf(stderr, "%s: `free F px py pz qw qx qy qz` needs the pose's seven numbers\n", argv[2]);
      return 1;
    }
    pin::urdf::buildModel(argv[1], pin::JointModelFreeFlyer(), model);
  } else {
    pin::urdf::buildModel(argv[1], model);
  }
  model.gravity.linear() = gravity;
  for (const auto& [name, a] : armatures) model.armature[model.joints[model.getJointId(name)].idx_v()] = a;
  const int n = int(joints.size()) + (free >= 0 ? 6 : 0);
  if (model.nv != n) {
    std::fprintf(stderr, "%s: %d coordinates, Pinocchio's model has nv = %d\n", argv[2], n, model.nv);
    return 1;
  }
  if (int(q_ours.size()) != n || int(v_ours.size()) != n || int(tau_ours.size()) != n) {
    std::fprintf(stderr, "%s: q, v and tau need %d values each\n", argv[2], n);
    return 1;
  }
  // Our coordinate i is Pinocchio's velocity entry vidx[i]; a revolute (`continuous`)
  // joint's configuration is (cos, sin), a prismatic one's the value; the free flyer's is
  // (position, quaternion x y z w), its velocity our six rates (body frame).
  std::vector<int> vidx(n);
  Eigen::VectorXd q = pin::neutral(model), v = Eigen::VectorXd::Zero(model.nv), tau = v;
  if (free >= 0) {
    const auto& root = model.joints[1];  // the URDF parser's root joint
    if (root.shortname() != "JointModelFreeFlyer") {
      std::fprintf(stderr, "%s: Pinocchio's first joint is %s, not the free flyer\n", argv[1], root.shortname().c_str());
      return 1;
    }
    for (int k = 0; k < 6; ++k) {
      if (q_ours[free + k] != 0.0) {
        std::fprintf(stderr, "%s: the free joint's q must be zero (the chart centred on the body)\n", argv[2]);
        return 1;
      }
    }
    Eigen::Quaterniond orientation(pose[3], pose[4], pose[5], pose[6]);
    orientation.normalize();
    q.segment<3>(root.idx_q()) << pose[0], pose[1], pose[2];
    q.segment<4>(root.idx_q() + 3) = orientation.coeffs();  // x, y, z, w
  }
  for (int i = 0, k = 0; i < n; ++i) {
    if (free >= 0 && i >= free && i < free + 6) {
      vidx[i] = model.joints[1].idx_v() + (i - free);
      v(vidx[i]) = v_ours[i];
      tau(vidx[i]) = tau_ours[i];
      continue;
    }
    const std::string& name = joints[k++];
    const auto id = model.getJointId(name);
    if (id >= model.joints.size()) {
      std::fprintf(stderr, "%s: no joint `%s` in the URDF\n", argv[2], name.c_str());
      return 1;
    }
    const auto& j = model.joints[id];
    vidx[i] = j.idx_v();
    if (j.nq() == 2) {
      q(j.idx_q()) = std::cos(q_ours[i]);
      q(j.idx_q() + 1) = std::sin(q_ours[i]);
    } else {
      q(j.idx_q()) = q_ours[i];
    }
    v(j.idx_v()) = v_ours[i];
    tau(j.idx_v()) = tau_ours[i];
  }
  std::vector<pin::RigidConstraintModel> cmodels;
  for (const auto& c : closures) {
    const auto ia = model.getFrameId(c + ".a"), ib = model.getFrameId(c + ".b");
    if (ia >= model.frames.size() || ib >= model.frames.size()) {
      std::fprintf(stderr, "%s: no frames `%s.a`, `%s.b` in the URDF\n", argv[2], c.c_str(), c.c_str());
      return 1;
    }
    const pin::Frame& fa = model.frames[ia];
    const pin::Frame& fb = model.frames[ib];
    const bool swap = fa.parentJoint == 0;
    const pin::Frame& f1 = swap ? fb : fa;
    const pin::Frame& f2 = swap ? fa : fb;
    cmodels.emplace_back(pin::CONTACT_3D, model, f1.parentJoint, f1.placement, f2.parentJoint, f2.placement,
                         pin::LOCAL_WORLD_ALIGNED);
  }
  // The stance: the closures and every contact point held where it is in the world (the
  // second frame the universe's, at the point's place at q: no Baumgarte term reads it).
  std::vector<pin::RigidConstraintModel> stance = cmodels;
  {
    pin::Data at_q(model);
    pin::framesForwardKinematics(model, at_q, q);
    for (const auto& c : contacts) {
      const auto id = model.getFrameId(c + ".point");
      if (id >= model.frames.size()) {
        std::fprintf(stderr, "%s: no frame `%s.point` in the URDF\n", argv[2], c.c_str());
        return 1;
      }
      const pin::Frame& f = model.frames[id];
      stance.emplace_back(pin::CONTACT_3D, model, f.parentJoint, f.placement, 0, at_q.oMf[id], pin::LOCAL_WORLD_ALIGNED);
    }
  }
  std::vector<pin::RigidConstraintData> cdatas, stance_datas;
  for (const auto& cm : cmodels) cdatas.emplace_back(cm);
  for (const auto& cm : stance) stance_datas.emplace_back(cm);
  pin::Data data(model), stance_data(model);
  pin::initConstraintDynamics(model, data, cmodels, cdatas);
  pin::initConstraintDynamics(model, stance_data, stance, stance_datas);

  // Median over batches of the time of one call, on states that change every call (a
  // rate: a revolute joint's (cos, sin) stays a unit pair). `call` returns Pinocchio's
  // own reference to its q̈ (no copy in the loop).
  auto median_ns = [&](auto&& call) {
    const int batch = 20000, batches = 15;
    std::vector<double> times;
    Eigen::VectorXd vv = v;
    double sink = 0;
    for (int b = 0; b < batches; ++b) {
      auto t0 = std::chrono::steady_clock::now();
      for (int i = 0; i < batch; ++i) {
        vv(0) = v(0) + 1e-12 * i;
        sink += call(vv)(0);
      }
      auto t1 = std::chrono::steady_clock::now();
      times.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / batch);
    }
    std::sort(times.begin(), times.end());
    if (!std::isfinite(sink)) std::fprintf(stderr, "non-finite q̈ while timing\n");
    return times[times.size() / 2];
  };
  auto timed_on = [&](pin::Data& d, const std::vector<pin::RigidConstraintModel>& cm,
                      std::vector<pin::RigidConstraintData>& cd, pin::ProximalSettings& settings,
                      Eigen::VectorXd& out) {
    out = pin::constraintDynamics(model, d, q, v, tau, cm, cd, settings);
    return median_ns([&](const Eigen::VectorXd& vv) -> const Eigen::VectorXd& {
      return pin::constraintDynamics(model, d, q, vv, tau, cm, cd, settings);
    });
  };
  auto timed = [&](pin::ProximalSettings& settings, Eigen::VectorXd& out) {
    return timed_on(data, cmodels, cdatas, settings, out);
  };
  // The fewest proximal iterations whose q̈ is the converged one to 1e-10 of its largest
  // entry: where rows repeat each other the stopping test never passes and every call runs
  // to the cap, while q̈ is exact after two or three. An oracle's choice (found against the capped answer, at this
  // one state): Pinocchio's lower bound, which a user cannot know in advance.
  auto fewest = [&](pin::Data& d, const std::vector<pin::RigidConstraintModel>& cm,
                    std::vector<pin::RigidConstraintData>& cd, const Eigen::VectorXd& exact, int cap) {
    const double scale = exact.lpNorm<Eigen::Infinity>();
    for (int k = 1; k < cap; ++k) {
      pin::ProximalSettings s(1e-12, 1e-8, k);
      const Eigen::VectorXd a = pin::constraintDynamics(model, d, q, v, tau, cm, cd, s);
      if ((a - exact).lpNorm<Eigen::Infinity>() <= 1e-10 * scale) return k;
    }
    return std::max(cap, 1);
  };
  pin::ProximalSettings converged(1e-12, 1e-8, 100), one(1e-12, 1e-8, 1);
  Eigen::VectorXd qdd, qdd_one, qdd_few;
  const double ns = timed(converged, qdd);
  pin::constraintDynamics(model, data, q, v, tau, cmodels, cdatas, converged);
  const int iterations = converged.iter;
  const double ns_one = timed(one, qdd_one);
  pin::ProximalSettings few(1e-12, 1e-8, fewest(data, cmodels, cdatas, qdd, iterations));
  const double ns_few = timed(few, qdd_few);
  auto print = [&](const char* key, const Eigen::VectorXd& x) {
    std::printf("\"%s\": [", key);
    for (int i = 0; i < n; ++i) std::printf("%s%.17g", i ? ", " : "", x(vidx[i]));
    std::printf("]");
  };
  std::printf("{");
  print("qdd", qdd);
  std::printf(", \"iterations\": %d, \"median_ns\": %.3f, ", iterations, ns);
  print("one_iteration_qdd", qdd_one);
  std::printf(", \"one_iteration_ns\": %.3f, ", ns_one);
  print("fewest_qdd", qdd_few);
  std::printf(", \"fewest_iterations\": %d, \"fewest_ns\": %.3f", few.max_iter, ns_few);
  if (cmodels.empty()) {
    // Nothing to hold: Pinocchio's own call for that is `aba`, faster than
    // `constraintDynamics` with no constraints, so it is the peer.
    pin::Data aba_data(model);
    const Eigen::VectorXd qdd_aba = pin::aba(model, aba_data, q, v, tau);
    const double ns_aba = median_ns([&](const Eigen::VectorXd& vv) -> const Eigen::VectorXd& {
      return pin::aba(model, aba_data, q, vv, tau);
    });
    std::printf(", ");
    print("aba_qdd", qdd_aba);
    std::printf(", \"aba_ns\": %.3f", ns_aba);
  }
  if (!contacts.empty()) {
    pin::ProximalSettings held(1e-12, 1e-8, 100);
    Eigen::VectorXd qdd_stance, qdd_stance_few;
    const double ns_stance = timed_on(stance_data, stance, stance_datas, held, qdd_stance);
    pin::constraintDynamics(model, stance_data, q, v, tau, stance, stance_datas, held);
    pin::ProximalSettings held_few(1e-12, 1e-8, fewest(stance_data, stance, stance_datas, qdd_stance, held.iter));
    const double ns_stance_few = timed_on(stance_data, stance, stance_datas, held_few, qdd_stance_few);
    std::printf(", ");
    print("stance_qdd", qdd_stance);
    std::printf(", \"stance_iterations\": %d, \"stance_median_ns\": %.3f, ", held.iter, ns_stance);
    print("stance_fewest_qdd", qdd_stance_few);
    std::printf(", \"stance_fewest_iterations\": %d, \"stance_fewest_ns\": %.3f", held_few.max_iter, ns_stance_few);
  }
  std::printf("}\n");
  return 0;
}
