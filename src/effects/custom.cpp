// custom {name, parameters, scale, scale_left, scale_right, wheelbase_factor}: a user's own
// systematic effect, written in YAML as expressions over each increment's motion (v, kappa, r,
// dir, turn, s, t) and its own parameters, evaluated by muparser. World and model: the same
// factors per sample / per piece from its Motion, exactly as turn_dependent_wheelbase does, so
// the engine has no special case for it.
//
// muparser parsers are not thread-safe (each keeps its stack and binds variables by address),
// so every instance (one per instantiate: one per simulator, one per resolve) compiles its own
// evaluator, and a mutex guards it should one instance ever be shared. Expressions are compiled
// once per instance to bytecode; evaluating them allocates nothing.
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

enum Variable { kV, kKappa, kR, kDir, kTurn, kS, kT, kVariables };

/// One compiled expression with its own variable storage (not movable: muparser keeps the
/// variables' addresses).
class Compiled {
 public:
  Compiled(const std::string& text, const std::vector<std::string>& parameters,
           const std::vector<double>& values) {
    for (int i = 0; i < kVariables; ++i) parser_.DefineVar(custom_effect_variables()[i], &vars_[i]);
    for (std::size_t i = 0; i < parameters.size(); ++i) parser_.DefineConst(parameters[i], values[i]);
    parser_.SetExpr(text);
    parser_.Eval();  // compiles to bytecode: an unknown name or a syntax error throws here
    if (parser_.GetNumResults() != 1) {
      throw mu::Parser::exception_type("one expression expected, got " +
                                       std::to_string(parser_.GetNumResults()) + " separated by ','");
    }
  }
  Compiled(const Compiled&) = delete;
  Compiled& operator=(const Compiled&) = delete;

  /// The strongest dependence of the expression on the motion (GetUsedVar parses again and
  /// drops the bytecode: only for checking a definition).
  effects::Dependence dependence() const {
    effects::Dependence d = effects::Dependence::none;
    for (const auto& [name, address] : parser_.GetUsedVar()) {
      const bool history = address == &vars_[kS] || address == &vars_[kT];
      d = std::max(d, history ? effects::Dependence::history : effects::Dependence::increment);
    }
    return d;
  }
  double eval(const effects::Motion& m) {
    vars_[kV] = m.v_mps;
    vars_[kKappa] = m.kappa_per_m;
    vars_[kR] = m.r;
    vars_[kDir] = m.dir;
    vars_[kTurn] = m.turn;
    // s and t at the middle of the increment: a model piece (many samples long) then gets the
    // mean of a linear dependence exactly, as the simulator's samples sum it.
    vars_[kS] = m.s_m + 0.25 * (std::abs(m.dL_m) + std::abs(m.dR_m));
    vars_[kT] = m.t_s + 0.5 * m.dt_s;
    return parser_.Eval();
  }

 private:
  std::array<double, kVariables> vars_{};
  mu::Parser parser_;
};

[[noreturn]] void fail_at(const CustomEffect::Expression& e, const std::string& what) {
  throw InputError(e.file, e.line, e.key, what);
}

class Custom final : public effects::Effect {
 public:
  Custom(std::shared_ptr<const CustomEffect> def, const std::vector<double>& values)
      : def_(std::move(def)) {
    const std::array<const CustomEffect::Expression*, 4> exprs{&def_->scale, &def_->scale_left,
                                                               &def_->scale_right, &def_->wheelbase_factor};
    for (std::size_t i = 0; i < exprs.size(); ++i) {
      if (exprs[i]->text.empty()) continue;
      try {
        compiled_[i] = std::make_unique<Compiled>(exprs[i]->text, def_->parameters, values);
      } catch (const mu::Parser::exception_type& e) {
        fail_at(*exprs[i], e.GetMsg());
      }
    }
  }
  effects::Dependence dependence() const override {
    return static_cast<effects::Dependence>(def_->dependence);
  }
  void systematic(const effects::Motion& m, effects::Systematic& f) const override {
    const std::lock_guard<std::mutex> lock(mutex_);
    const double scale = value(0, m), wheelbase = value(3, m);
    f.scale_left *= scale * value(1, m);
    f.scale_right *= scale * value(2, m);
    if (!(wheelbase > 0.0)) fail(3, m, wheelbase, "must be > 0");
    f.wheelbase_factor *= wheelbase;
  }

 private:
  const CustomEffect::Expression& expression(std::size_t i) const {
    return i == 0 ? def_->scale : i == 1 ? def_->scale_left : i == 2 ? def_->scale_right : def_->wheelbase_factor;
  }
  double value(std::size_t i, const effects::Motion& m) const {
    if (!compiled_[i]) return 1.0;
    double x = 0.0;
    try {
      x = compiled_[i]->eval(m);
    } catch (const mu::Parser::exception_type& e) {
      fail_at(expression(i), e.GetMsg());
    }
    if (!std::isfinite(x)) fail(i, m, x, "must be finite");
    return x;
  }
  [[noreturn]] void fail(std::size_t i, const effects::Motion& m, double x, const char* what) const {
    fail_at(expression(i), "evaluates to " + format_number(x) + " (" + what + ") at v = " +
                               format_number(m.v_mps) + ", kappa = " + format_number(m.kappa_per_m) +
                               ", r = " + format_number(m.r) + ", dir = " + std::to_string(m.dir) +
                               ", turn = " + std::to_string(m.turn) + ", s = " +
                               format_number(m.s_m + 0.25 * (std::abs(m.dL_m) + std::abs(m.dR_m))) +
                               ", t = " + format_number(m.t_s + 0.5 * m.dt_s) +
                               (std::isnan(m.t_s) ? " (the path has no times here)" : ""));
  }

  std::shared_ptr<const CustomEffect> def_;
  mutable std::array<std::unique_ptr<Compiled>, 4> compiled_;
  mutable std::mutex mutex_;
};

}  // namespace

const std::vector<std::string>& custom_effect_variables() {
  static const std::vector<std::string> names{"v", "kappa", "r", "dir", "turn", "s", "t"};
  return names;
}

std::string check_custom_name(const std::string& name) {
  if (name.empty()) return "must not be empty";
  bool ok = !(name[0] >= '0' && name[0] <= '9');
  for (char c : name) {
    ok = ok && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_');
  }
  if (!ok) return "must be letters, digits and '_', not starting with a digit: " + quote(name);
  for (const std::string& v : custom_effect_variables()) {
    if (name == v) return quote(name) + " is a per-sample variable";
  }
  return "";
}

namespace {

/// "" or muparser's message; `dependence` (when given) is raised to the expression's.
std::string check_expression(const std::string& text, const std::vector<std::string>& parameters,
                             effects::Dependence* dependence) {
  try {
    const Compiled c(text, parameters, std::vector<double>(parameters.size(), 0.0));
    if (dependence) *dependence = std::max(*dependence, c.dependence());
  } catch (const mu::Parser::exception_type& e) {
    return e.GetMsg();
  }
  return "";
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
  return check_expression(text, parameters, nullptr);
}

bool CustomEffect::operator==(const CustomEffect& o) const {
  auto same = [](const Expression& a, const Expression& b) { return a.text == b.text; };
  return name == o.name && parameters == o.parameters && same(scale, o.scale) &&
         same(scale_left, o.scale_left) && same(scale_right, o.scale_right) &&
         same(wheelbase_factor, o.wheelbase_factor);
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
  if (start.size() != def.parameters.size()) fail_at(where, "one starting value per parameter");
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    if (const std::string e = check_custom_name(def.parameters[i]); !e.empty()) fail_at(where, "parameter " + e);
    for (std::size_t j = 0; j < i; ++j) {
      if (def.parameters[j] == def.parameters[i]) fail_at(where, "parameter " + quote(def.parameters[i]) + " given twice");
    }
  }
  def.info = EffectInfo{};
  def.info.name = def.name;
  for (const auto& [key, e] : {std::pair{"scale", &def.scale}, std::pair{"scale_left", &def.scale_left},
                               std::pair{"scale_right", &def.scale_right},
                               std::pair{"wheelbase_factor", &def.wheelbase_factor}}) {
    if (!e->text.empty()) def.info.summary += std::string(def.info.summary.empty() ? "" : ", ") + key + " = " + e->text;
  }
  def.info.physics = "custom effect " + def.name + " (" + def.info.summary + ")";
  def.info.signature = "a user-defined hypothesis";
  def.info.systematic = true;
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    // Unbounded and signed: the fit works on the value itself, stepping by a hundredth of its
    // size (at least 0.01) from the start.
    const double step = std::max(0.01, 0.01 * std::abs(start[i]));
    def.info.parameters.push_back({def.parameters[i], "", -1e300, 1e300, false, false, start[i], start[i] + step});
  }
  effects::Dependence dependence = effects::Dependence::none;
  for (const auto* e : {&def.scale, &def.scale_left, &def.scale_right, &def.wheelbase_factor}) {
    if (e->text.empty()) continue;
    if (const std::string error = check_expression(e->text, def.parameters, &dependence); !error.empty()) {
      fail_at(*e, error);
    }
  }
  def.dependence = static_cast<int>(dependence);
  auto shared = std::make_shared<const CustomEffect>(std::move(def));
  return EffectSpec{shared->name, start, {}, shared};
}

namespace effects {

std::unique_ptr<Effect> make_custom(const EffectSpec& spec) {
  return std::make_unique<Custom>(spec.custom, spec.values);
}

}  // namespace effects
}  // namespace odomcov
