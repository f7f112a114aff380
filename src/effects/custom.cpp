// custom {name, parameters, random, scale, scale_left, scale_right, wheelbase_factor, lateral,
// noise}: a user's own effect, written in YAML as expressions over each increment's motion (v,
// kappa, r, dir, turn, s, t, a, omega, theta, heading) and its own parameters, evaluated by
// muparser. World and model go through the ordinary Effect interface, so the engine has no
// special case for it:
//  * the expressions give the increment's systematic terms (Systematic: wheel scales, wheelbase
//    factor, lateral slip, noise factor), on the world side per leg or sample, on the model side
//    per piece (resolve cuts pieces finer where a smooth history term is not linear along them);
//  * a parameter under `random: {p: sd}` is drawn once per run from N(value, sd^2) in the
//    effect's own per-run stream slot (world: the simulator composes run_systematic with the
//    leg's other terms for every leg of every run), and is a standard-normal per-run constant of
//    the model whose column is what the draw does to the piece's motion (model()).
//
// muparser parsers are not thread-safe (each keeps its stack and binds variables by address),
// so every instance (one per instantiate: one per simulator, one per resolve) compiles its own
// evaluator for the systematic terms, guarded by a mutex, and keeps a pool of evaluators for the
// per-run terms, which the simulator's threads take one at a time. Expressions are compiled
// once per evaluator to bytecode; evaluating them allocates nothing.
#include <muParser.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <utility>

#include "effects/effect.hpp"
#include "odomcov/base/format.hpp"

namespace odomcov {
namespace {

enum Variable { kV, kKappa, kR, kDir, kTurn, kS, kT, kA, kOmega, kTheta, kHeading, kVariables };
/// Variables from kA on were added after custom effects were released: a parameter may take
/// their names (and then hides the variable in its effect).
constexpr int kFirstShadowable = kA;
/// The expressions of a definition, in CustomEffect::expressions' order.
enum Slot { kScale, kScaleLeft, kScaleRight, kWheelbase, kLateral, kNoise, kSlots };
constexpr std::array<double, kSlots> kNeutral{1.0, 1.0, 1.0, 1.0, 0.0, 1.0};

/// The values an evaluator's expressions read: the motion's variables and the drawn parameters.
struct Storage {
  std::array<double, kVariables> vars{};
  std::array<double, kMaxRandomParameters> random{};
};

/// Whether `name` is one of the definition's parameters.
bool is_parameter(const std::vector<std::string>& parameters, const std::string& name) {
  for (const std::string& p : parameters) {
    if (p == name) return true;
  }
  return false;
}

/// One compiled expression bound to a Storage (not movable: muparser keeps the addresses). The
/// parameters are constants, except the random ones, which read `storage.random`.
class Compiled {
 public:
  Compiled(const std::string& text, const std::vector<std::string>& parameters,
           const std::vector<std::string>& random, const std::vector<double>& values, Storage& storage)
      : storage_(&storage) {
    const std::vector<std::string>& names = custom_effect_variables();
    for (int i = 0; i < kVariables; ++i) {
      if (i >= kFirstShadowable && is_parameter(parameters, names[i])) continue;
      parser_.DefineVar(names[i], &storage.vars[i]);
    }
    for (std::size_t i = 0; i < parameters.size(); ++i) {
      std::size_t j = 0;
      while (j < random.size() && random[j] != parameters[i]) ++j;
      if (j < random.size()) {
        storage.random[j] = values[i];
        parser_.DefineVar(parameters[i], &storage.random[j]);
      } else {
        parser_.DefineConst(parameters[i], values[i]);
      }
    }
    parser_.SetExpr(text);
    parser_.Eval();  // compiles to bytecode: an unknown name or a syntax error throws here
    if (parser_.GetNumResults() != 1) {
      throw mu::Parser::exception_type("one expression expected, got " +
                                       std::to_string(parser_.GetNumResults()) + " separated by ','");
    }
  }
  Compiled(const Compiled&) = delete;
  Compiled& operator=(const Compiled&) = delete;

  /// The motion variables the expression reads, one bit per Variable (GetUsedVar parses again
  /// and drops the bytecode: only for checking a definition).
  unsigned used() const {
    unsigned mask = 0;
    for (const auto& [name, address] : parser_.GetUsedVar()) {
      for (int i = 0; i < kVariables; ++i) mask |= address == &storage_->vars[i] ? 1u << i : 0u;
    }
    return mask;
  }
  double eval() { return parser_.Eval(); }

 private:
  Storage* storage_;
  mu::Parser parser_;
};

/// The values of the variables for an increment: s, t and theta (so heading) at its middle, so
/// that a model piece many samples long gets exactly the mean that a linear dependence has over
/// its samples; the others are the increment's own.
std::array<double, kVariables> variables_of(const effects::Motion& m) {
  std::array<double, kVariables> v{};
  v[kV] = m.v_mps;
  v[kKappa] = m.kappa_per_m;
  v[kR] = m.r;
  v[kDir] = m.dir;
  v[kTurn] = m.turn;
  v[kS] = m.s_m + 0.25 * (std::abs(m.dL_m) + std::abs(m.dR_m));
  v[kT] = m.t_s + 0.5 * m.dt_s;
  v[kA] = m.a_mps2;
  v[kOmega] = m.omega_radps;
  v[kTheta] = m.theta_rad + 0.5 * m.turn_rad;
  v[kHeading] = m.heading0_rad + v[kTheta];
  return v;
}

/// Every expression of a definition compiled against one Storage.
class Evaluator {
 public:
  Evaluator(const CustomEffect& def, const std::vector<double>& values) {
    const auto expressions = def.expressions();
    for (std::size_t i = 0; i < expressions.size(); ++i) {
      const CustomEffect::Expression& e = *expressions[i].second;
      if (e.text.empty()) continue;
      try {
        compiled_[i] = std::make_unique<Compiled>(e.text, def.parameters, def.random, values, storage_);
      } catch (const mu::Parser::exception_type& error) {
        throw InputError(e.file, e.line, e.key, error.GetMsg());
      }
    }
  }
  Evaluator(const Evaluator&) = delete;
  Evaluator& operator=(const Evaluator&) = delete;

  void at(const effects::Motion& m) { storage_.vars = variables_of(m); }
  void set_random(std::size_t j, double value) { storage_.random[j] = value; }
  double random(std::size_t j) const { return storage_.random[j]; }
  bool has(int slot) const { return compiled_[static_cast<std::size_t>(slot)] != nullptr; }
  /// The expression's value (its neutral value when absent); muparser's errors propagate.
  double eval(int slot) {
    auto& c = compiled_[static_cast<std::size_t>(slot)];
    return c ? c->eval() : kNeutral[static_cast<std::size_t>(slot)];
  }
  const Storage& storage() const { return storage_; }

 private:
  Storage storage_;
  std::array<std::unique_ptr<Compiled>, kSlots> compiled_;
};

[[noreturn]] void fail_at(const CustomEffect::Expression& e, const std::string& what) {
  throw InputError(e.file, e.line, e.key, what);
}

/// The definition's parameters that are drawn per run, as indices into its parameters.
std::vector<std::size_t> random_indices(const CustomEffect& def) {
  std::vector<std::size_t> out;
  for (const std::string& r : def.random) {
    for (std::size_t i = 0; i < def.parameters.size(); ++i) {
      if (def.parameters[i] == r) out.push_back(i);
    }
  }
  return out;
}

class Custom final : public effects::Effect {
 public:
  Custom(std::shared_ptr<const CustomEffect> def, const std::vector<double>& values)
      : def_(std::move(def)), values_(values), random_(random_indices(*def_)), nominal_(*def_, values_) {
    for (std::size_t j = 0; j < random_.size(); ++j) per_run_ = per_run_ || sd(j) > 0.0;
  }

  effects::Dependence dependence() const override {
    return static_cast<effects::Dependence>(def_->dependence);
  }
  bool refines() const override { return def_->smooth_history; }
  void systematic(const effects::Motion& m, effects::Systematic& f) const override {
    const std::lock_guard<std::mutex> lock(mutex_);
    fold(nominal_, m, f);
  }

  // ---- World side: the random parameters, drawn once per run in the effect's own slot.
  bool stochastic() const override { return per_run_; }
  bool per_run_systematic() const override { return per_run_; }
  void begin_run(effects::RunState& state, const effects::Draws& draws) const override {
    for (std::size_t j = 0; j < random_.size(); ++j) {
      state.value[j] = values_[random_[j]] + sd(j) * draws.run_normal(static_cast<std::uint32_t>(j));
    }
  }
  void run_systematic(const effects::Motion& m, const effects::RunState& state,
                      effects::Systematic& f) const override {
    const Lease lease(*this);
    for (std::size_t j = 0; j < random_.size(); ++j) lease.evaluator->set_random(j, state.value[j]);
    fold(*lease.evaluator, m, f);
  }

  // ---- Model side: each random parameter is a standard-normal per-run constant z_j, p_j =
  // value + sd z_j. Its column is the change of the piece's true motion (heading change a,
  // centre travel d, lateral slip l) per unit z, from the points p_j +- sqrt(3) sd (the
  // Gauss-Hermite points: the column is E[X z] exactly for motions up to cubic in p_j), the
  // other parameters at their values; a heading change is written as the wheel errors that
  // turn the same at the piece's true wheelbase.
  int run_constants() const override { return static_cast<int>(random_.size()); }
  void model(effects::PieceModel& piece) const override {
    if (random_.empty()) return;
    const effects::Systematic others = effects::others_systematic(piece, this);
    const double b0 = piece.wheelbase_factor * piece.wheelbase_m;
    const std::lock_guard<std::mutex> lock(mutex_);
    for (std::size_t j = 0; j < random_.size(); ++j) {
      if (!(sd(j) > 0.0)) {
        piece.run_columns.emplace_back(Eigen::Vector3d::Zero());
        continue;
      }
      const double h = std::sqrt(3.0) * sd(j), value = values_[random_[j]];
      nominal_.set_random(j, value + h);
      const Eigen::Vector3d up = piece_motion(piece, others);
      nominal_.set_random(j, value - h);
      const Eigen::Vector3d down = piece_motion(piece, others);
      nominal_.set_random(j, value);
      const Eigen::Vector3d delta = (up - down) / (2.0 * std::sqrt(3.0));  // (da, dd, dl) per unit z
      piece.run_columns.emplace_back(delta.y() - 0.5 * b0 * delta.x(), delta.y() + 0.5 * b0 * delta.x(), delta.z());
    }
  }

 private:
  /// An evaluator of the pool, returned on destruction (exceptions included).
  struct Lease {
    explicit Lease(const Custom& c) : owner(&c) {
      const std::lock_guard<std::mutex> lock(c.pool_mutex_);
      if (c.pool_.empty()) {
        evaluator = std::make_unique<Evaluator>(*c.def_, c.values_);
      } else {
        evaluator = std::move(c.pool_.back());
        c.pool_.pop_back();
      }
    }
    ~Lease() {
      const std::lock_guard<std::mutex> lock(owner->pool_mutex_);
      owner->pool_.push_back(std::move(evaluator));
    }
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    const Custom* owner;
    std::unique_ptr<Evaluator> evaluator;
  };

  double sd(std::size_t j) const { return values_[def_->parameters.size() + j]; }

  /// The piece's true (heading change, centre travel, lateral slip) with this effect's terms from
  /// the nominal evaluator (as its random parameters are set) composed with `others`.
  Eigen::Vector3d piece_motion(const effects::PieceModel& piece, const effects::Systematic& others) const {
    effects::Systematic s = others;
    fold(nominal_, *piece.motion, s);
    const ArcSegment travel = s.travel(piece.encoder.left_m, piece.encoder.right_m);
    const double mean_travel = 0.5 * (std::abs(piece.encoder.left_m) + std::abs(piece.encoder.right_m));
    return {travel.heading_change_rad(s.wheelbase_factor * piece.wheelbase_m), travel.center_m(),
            s.lateral * mean_travel};
  }

  /// Evaluates every expression at `m` and composes the terms into `f`.
  void fold(Evaluator& ev, const effects::Motion& m, effects::Systematic& f) const {
    ev.at(m);
    const double scale = value(ev, kScale, m), wheelbase = value(ev, kWheelbase, m);
    f.scale_left *= scale * value(ev, kScaleLeft, m);
    f.scale_right *= scale * value(ev, kScaleRight, m);
    if (!(wheelbase > 0.0)) fail(ev, kWheelbase, m, wheelbase, "must be > 0");
    f.wheelbase_factor *= wheelbase;
    f.lateral += value(ev, kLateral, m);
    const double noise = value(ev, kNoise, m);
    if (!(noise >= 0.0)) fail(ev, kNoise, m, noise, "must be >= 0");
    f.noise_factor *= noise;
  }
  double value(Evaluator& ev, int slot, const effects::Motion& m) const {
    if (!ev.has(slot)) return kNeutral[static_cast<std::size_t>(slot)];
    double x = 0.0;
    try {
      x = ev.eval(slot);
    } catch (const mu::Parser::exception_type& e) {
      fail_at(*def_->expressions()[static_cast<std::size_t>(slot)].second, e.GetMsg());
    }
    if (!std::isfinite(x)) fail(ev, slot, m, x, "must be finite");
    return x;
  }
  /// Bad input at the expression: its value, the motion (the variables as the expression saw
  /// them) and, for a random parameter, the value drawn or tried.
  [[noreturn]] void fail(const Evaluator& ev, int slot, const effects::Motion& m, double x,
                         const char* what) const {
    const std::array<double, kVariables> v = variables_of(m);
    const std::vector<std::string>& names = custom_effect_variables();
    std::string where;
    for (int i = 0; i < kVariables; ++i) {
      if (i >= kFirstShadowable && is_parameter(def_->parameters, names[i])) continue;  // hidden
      const bool integer = i == kDir || i == kTurn;
      where += (where.empty() ? "" : ", ") + names[i] + " = " +
               (integer ? std::to_string(static_cast<int>(v[i])) : format_number(v[i]));
    }
    for (std::size_t j = 0; j < random_.size(); ++j) {
      where += ", " + def_->random[j] + " = " + format_number(ev.random(j)) + " (drawn per run from N(" +
               format_number(values_[random_[j]]) + ", " + format_number(sd(j)) + "^2))";
    }
    fail_at(*def_->expressions()[static_cast<std::size_t>(slot)].second,
            "evaluates to " + format_number(x) + " (" + what + ") at " + where +
                (std::isnan(m.t_s) ? " (the path has no times here)" : ""));
  }

  std::shared_ptr<const CustomEffect> def_;
  std::vector<double> values_;
  std::vector<std::size_t> random_;  // indices of the random parameters in the definition's
  bool per_run_ = false;             // some random parameter has sd > 0
  mutable Evaluator nominal_;        // the systematic terms (and the model's columns)
  mutable std::mutex mutex_;         // guards nominal_
  mutable std::vector<std::unique_ptr<Evaluator>> pool_;  // for run_systematic
  mutable std::mutex pool_mutex_;
};

}  // namespace

const std::vector<std::string>& custom_effect_variables() {
  static const std::vector<std::string> names{"v", "kappa", "r", "dir", "turn", "s",
                                              "t", "a", "omega", "theta", "heading"};
  return names;
}

std::vector<std::pair<const char*, CustomEffect::Expression*>> CustomEffect::expressions() {
  return {{"scale", &scale},         {"scale_left", &scale_left}, {"scale_right", &scale_right},
          {"wheelbase_factor", &wheelbase_factor}, {"lateral", &lateral}, {"noise", &noise}};
}

std::vector<std::pair<const char*, const CustomEffect::Expression*>> CustomEffect::expressions() const {
  std::vector<std::pair<const char*, const Expression*>> out;
  for (const auto& [slot, e] : const_cast<CustomEffect*>(this)->expressions()) out.emplace_back(slot, e);
  return out;
}

std::string check_custom_name(const std::string& name) {
  if (name.empty()) return "must not be empty";
  bool ok = !(name[0] >= '0' && name[0] <= '9');
  for (char c : name) {
    ok = ok && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_');
  }
  if (!ok) return "must be letters, digits and '_', not starting with a digit: " + quote(name);
  const std::vector<std::string>& variables = custom_effect_variables();
  for (int i = 0; i < kFirstShadowable; ++i) {
    if (name == variables[static_cast<std::size_t>(i)]) return quote(name) + " is a per-sample variable";
  }
  return "";
}

namespace {

/// "" or muparser's message; `used` (when given) gets the bits of the motion variables read.
std::string check_expression(const std::string& text, const std::vector<std::string>& parameters,
                             const std::vector<std::string>& random, unsigned* used) {
  try {
    Storage storage;
    const Compiled c(text, parameters, random, std::vector<double>(parameters.size(), 0.0), storage);
    if (used) *used |= c.used();
  } catch (const mu::Parser::exception_type& e) {
    return e.GetMsg();
  }
  return "";
}

/// The parameters' names: identifiers, not reserved, none twice.
void check_parameter_names(const CustomEffect& def, const CustomEffect::Expression& where) {
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    if (const std::string e = check_custom_name(def.parameters[i]); !e.empty()) fail_at(where, "parameter " + e);
    for (std::size_t j = 0; j < i; ++j) {
      if (def.parameters[j] == def.parameters[i]) fail_at(where, "parameter " + quote(def.parameters[i]) + " given twice");
    }
  }
}

/// The random parameters: each a parameter of the effect, once, at most kMaxRandomParameters,
/// its sd finite and >= 0, and no parameter named like the sd's fit parameter sd_<p>.
void check_random(const CustomEffect& def, const std::vector<double>& start,
                  const CustomEffect::Expression& where) {
  if (def.random.size() > kMaxRandomParameters) {
    fail_at(where, "random: at most " + std::to_string(kMaxRandomParameters) + " parameters drawn per run");
  }
  for (std::size_t j = 0; j < def.random.size(); ++j) {
    const std::string& r = def.random[j];
    if (!is_parameter(def.parameters, r)) fail_at(where, "random: " + quote(r) + " is not a parameter of the effect");
    for (std::size_t k = 0; k < j; ++k) {
      if (def.random[k] == r) fail_at(where, "random: " + quote(r) + " given twice");
    }
    if (is_parameter(def.parameters, "sd_" + r)) {
      fail_at(where, "parameter 'sd_" + r + "' clashes with the fit name of random " + quote(r) + "'s sd");
    }
    const double sd = start[def.parameters.size() + j];
    if (!std::isfinite(sd)) fail_at(where, "random: the sd of " + quote(r) + " must be finite");
    if (sd < 0.0) fail_at(where, "random: the sd of " + quote(r) + " must be >= 0, got " + format_number(sd));
  }
}

/// The description fit and diagnose use (see CustomEffect::info).
EffectInfo custom_info(const CustomEffect& def, const std::vector<double>& start) {
  EffectInfo info;
  info.name = def.name;
  for (const auto& [key, e] : def.expressions()) {
    if (!e->text.empty()) info.summary += std::string(info.summary.empty() ? "" : ", ") + key + " = " + e->text;
  }
  for (std::size_t j = 0; j < def.random.size(); ++j) {
    info.summary += (j ? ", " : ", " + std::string("drawn per run: ")) + def.random[j] + " ~ N(value, sd_" +
                    def.random[j] + "^2)";
  }
  info.physics = "custom effect " + def.name + " (" + info.summary + ")";
  info.signature = "a user-defined hypothesis";
  info.systematic = !def.scale.text.empty() || !def.scale_left.text.empty() || !def.scale_right.text.empty() ||
                    !def.wheelbase_factor.text.empty() || !def.lateral.text.empty();
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    // Unbounded and signed: the fit works on the value itself, stepping by a hundredth of its
    // size (at least 0.01) from the start.
    const double step = std::max(0.01, 0.01 * std::abs(start[i]));
    info.parameters.push_back({def.parameters[i], "", -1e300, 1e300, false, false, start[i], start[i] + step});
  }
  for (std::size_t j = 0; j < def.random.size(); ++j) {
    // A size that may be 0 (square-root coordinate), neutral at 0. Its typical size, which sets
    // the fit's first step and box, is the starting sd, or a tenth of the parameter's value
    // (at least 1e-3) when the sd starts at 0.
    const double sd = start[def.parameters.size() + j];
    double value = 0.0;
    for (std::size_t i = 0; i < def.parameters.size(); ++i) value = def.parameters[i] == def.random[j] ? start[i] : value;
    const double typical = sd > 0.0 ? sd : std::max(1e-3, 0.1 * std::abs(value));
    EffectParameterInfo p{"sd_" + def.random[j], "", 0.0, 1e300, false, false, 0.0, typical};
    p.random_sd = true;
    info.parameters.push_back(p);
  }
  return info;
}

}  // namespace

std::string check_custom_expression(const std::string& text, const std::vector<std::string>& parameters) {
  // muparser reads a C string: a NUL would cut the expression silently, and control or
  // non-ASCII bytes cannot be part of a formula (nor be written back unchanged).
  for (const unsigned char c : text) {
    if (c < 0x20 || c > 0x7e) {
      char byte[8];
      std::snprintf(byte, sizeof byte, "0x%02x", c);
      return std::string("an expression holds printable ASCII only (found byte ") + byte + ")";
    }
  }
  return check_expression(text, parameters, {}, nullptr);
}

bool CustomEffect::operator==(const CustomEffect& o) const {
  if (name != o.name || parameters != o.parameters || random != o.random) return false;
  const auto mine = expressions(), theirs = o.expressions();
  for (std::size_t i = 0; i < mine.size(); ++i) {
    if (mine[i].second->text != theirs[i].second->text) return false;
  }
  return true;
}

bool EffectSpec::operator==(const EffectSpec& o) const {
  const bool same_custom = custom == o.custom || (custom && o.custom && *custom == *o.custom);
  return name == o.name && values == o.values && target == o.target && same_custom;
}

EffectSpec define_custom_effect(CustomEffect def, const std::vector<double>& start) {
  const CustomEffect::Expression where{"", def.file, def.line, def.key};
  if (const std::string e = check_custom_name(def.name); !e.empty()) fail_at(where, "name " + e);
  for (const effects::EffectType& t : effects::registry()) {
    if (t.info.name == def.name) fail_at(where, "name " + quote(def.name) + " is a catalogue effect");
  }
  if (start.size() != def.parameters.size() + def.random.size()) {
    fail_at(where, "one starting value per parameter, then one sd per random parameter");
  }
  check_parameter_names(def, where);
  check_random(def, start, where);
  unsigned used = 0;
  for (const auto& [key, e] : def.expressions()) {
    if (e->text.empty()) continue;
    if (const std::string error = check_expression(e->text, def.parameters, def.random, &used); !error.empty()) {
      fail_at(*e, error);
    }
  }
  constexpr unsigned kIncrement = 1u << kV | 1u << kKappa | 1u << kR | 1u << kDir | 1u << kTurn | 1u << kOmega;
  constexpr unsigned kSmooth = 1u << kS | 1u << kT | 1u << kTheta | 1u << kHeading;
  constexpr unsigned kHistory = kSmooth | 1u << kA;
  def.dependence = static_cast<int>((used & kHistory) ? effects::Dependence::history
                                    : (used & kIncrement) ? effects::Dependence::increment
                                                          : effects::Dependence::none);
  def.smooth_history = (used & kSmooth) != 0;
  def.info = custom_info(def, start);
  def.info.run_constants = static_cast<int>(def.random.size());
  def.info.uses_start_heading = (used & 1u << kHeading) != 0;
  def.info.uses_acceleration = (used & 1u << kA) != 0;
  auto shared = std::make_shared<const CustomEffect>(std::move(def));
  return EffectSpec{shared->name, start, {}, shared};
}

namespace effects {

std::unique_ptr<Effect> make_custom(const EffectSpec& spec) {
  return std::make_unique<Custom>(spec.custom, spec.values);
}

}  // namespace effects
}  // namespace odomcov
