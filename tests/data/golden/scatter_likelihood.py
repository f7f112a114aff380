#!/usr/bin/env python3
# Independent computation of the golden value of Likelihood.ScatterGoldenValue (tests/suite_test.cpp):
# exact rational arithmetic (fractions) for d' Sigma^-1 d (cofactor inverse) and det Sigma,
# 40-digit decimal logarithms. No Eigen, no Cholesky.
from fractions import Fraction as F
from decimal import Decimal, getcontext
getcontext().prec = 40
def det3(m):
    return (m[0][0]*(m[1][1]*m[2][2]-m[1][2]*m[2][1]) - m[0][1]*(m[1][0]*m[2][2]-m[1][2]*m[2][0])
            + m[0][2]*(m[1][0]*m[2][1]-m[1][1]*m[2][0]))
def quad(m, d):
    # d' adj(m) d / det(m)
    adj = [[None]*3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            r = [k for k in range(3) if k != j]; c = [k for k in range(3) if k != i]
            minor = m[r[0]][c[0]]*m[r[1]][c[1]] - m[r[0]][c[1]]*m[r[1]][c[0]]
            adj[i][j] = (-1)**(i+j) * minor
    return sum(d[i]*adj[i][j]*d[j] for i in range(3) for j in range(3)) / det3(m)
def dec(f): return Decimal(f.numerator) / Decimal(f.denominator)
pi = Decimal("3.141592653589793238462643383279502884197")
S1 = [[F("1e-4"), F("2e-5"), F("1e-6")], [F("2e-5"), F("4e-4"), F("-3e-6")], [F("1e-6"), F("-3e-6"), F("1e-6")]]
S2 = [[F("2e-4"), F(0), F(0)], [F(0), F("1e-4"), F("5e-6")], [F(0), F("5e-6"), F("4e-6")]]
runs = [  # (error, predicted mean, covariance)
    ([F("0.01"), F("0.02"), F("0.003")], [F("0.001"), F(0), F(0)], S1),
    ([F("-0.005"), F("0.01"), F("0.001")], [F("0.001"), F(0), F(0)], S1),
    ([F("0.002"), F("-0.004"), F("-0.002")], [F("0.0005"), F("0.001"), F(0)], S2),
]
n = len(runs)
m = [sum(e[i] - mu[i] for e, mu, _ in runs) / n for i in range(3)]
total = Decimal(0)
for e, mu, S in runs:
    d = [e[i] - mu[i] - m[i] for i in range(3)]
    logdet = dec(det3(S)).ln() + 3 * (2 * pi).ln()
    total += -dec(quad(S, d)) / 2 - Decimal(n - 1) / Decimal(n) * logdet / 2
print(total)
