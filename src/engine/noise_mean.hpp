// The noise-induced mean of the pose error (propagation.hpp, noise_induced_mean): its per-piece
// share, shared by noise_induced_mean (noise_mean.cpp) and the engine (propagation.cpp).
#pragma once

#include <complex>

namespace odomcov::detail {

/// One piece's share of the noise-induced mean, in the world frame, as x + i y: the piece starts
/// at the heading whose e^{i theta} is `rotation` (the caller's cosine and sine, so the engine
/// computes them once per piece for this and its pose update) with accumulated heading variance v0,
/// turns through a over the centre travel d, adds heading variance dv and has heading/travel noise
/// intensity n_td.
std::complex<double> noise_mean_of_piece(std::complex<double> rotation, double d, double a,
                                         double v0, double dv, double n_td);
/// The same with U = int_0^1 e^{i a u} du = sinc a + i (a/2) sinc^2(a/2) given (the engine has
/// the sines already), for a piece that also slips `lateral` [m] to the left along its arc
/// (effects' lateral slip): the slip turns with the heading error as the travel does, so it is
/// damped by the same E[exp(i phi)] = exp(-V/2).
std::complex<double> noise_mean_of_piece(std::complex<double> rotation, double d, double lateral,
                                         double a, std::complex<double> undamped, double v0,
                                         double dv, double n_td);

}  // namespace odomcov::detail
