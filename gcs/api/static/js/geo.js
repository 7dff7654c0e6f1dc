// WGS84 latitude and longitude <-> the scenario's local east/north metres: the service's own
// projection (planner/geo.py), an ellipsoidal Transverse Mercator whose central meridian passes
// through the origin, unit scale on it, the origin at (0, 0); Krüger's series to sixth order in
// the third flattening (Karney 2011), good to nanometres over a planning area.

const A_M = 6378137.0;
const F = 1 / 298.257223563;
const NEWTON_ITERATIONS = 6;

const SERIES = (() => {
  const n = F / (2 - F);
  const [n2, n3, n4, n5, n6] = [n ** 2, n ** 3, n ** 4, n ** 5, n ** 6];
  return {
    e: Math.sqrt(F * (2 - F)),
    rectifyingM: (A_M / (1 + n)) * (1 + n2 / 4 + n4 / 64 + n6 / 256),
    alpha: [
      n / 2 - (2 * n2) / 3 + (5 * n3) / 16 + (41 * n4) / 180 - (127 * n5) / 288 + (7891 * n6) / 37800,
      (13 * n2) / 48 - (3 * n3) / 5 + (557 * n4) / 1440 + (281 * n5) / 630 - (1983433 * n6) / 1935360,
      (61 * n3) / 240 - (103 * n4) / 140 + (15061 * n5) / 26880 + (167603 * n6) / 181440,
      (49561 * n4) / 161280 - (179 * n5) / 168 + (6601661 * n6) / 7257600,
      (34729 * n5) / 80640 - (3418889 * n6) / 1995840,
      (212378941 * n6) / 319334400,
    ],
    beta: [
      n / 2 - (2 * n2) / 3 + (37 * n3) / 96 - n4 / 360 - (81 * n5) / 512 + (96199 * n6) / 604800,
      n2 / 48 + n3 / 15 - (437 * n4) / 1440 + (46 * n5) / 105 - (1118711 * n6) / 3870720,
      (17 * n3) / 480 - (37 * n4) / 840 - (209 * n5) / 4480 + (5569 * n6) / 90720,
      (4397 * n4) / 161280 - (11 * n5) / 504 - (830251 * n6) / 7257600,
      (4583 * n5) / 161280 - (108847 * n6) / 3991680,
      (20648693 * n6) / 638668800,
    ],
  };
})();

const RAD = Math.PI / 180;

/** tan of the conformal latitude from tau = tan(geodetic latitude). */
function conformalTau(tau, e) {
  const sigma = Math.sinh(e * Math.atanh((e * tau) / Math.hypot(1, tau)));
  return tau * Math.hypot(1, sigma) - sigma * Math.hypot(1, tau);
}

function geodeticTau(tauP, e) {
  const oneMinusE2 = 1 - e * e;
  let tau = tauP;
  for (let i = 0; i < NEWTON_ITERATIONS; i += 1) {
    const tauIP = conformalTau(tau, e);
    tau +=
      (((tauP - tauIP) / Math.hypot(1, tauIP)) * (1 + oneMinusE2 * tau * tau)) /
      (oneMinusE2 * Math.hypot(1, tau));
  }
  return tau;
}

/** Unit-scale TM: [x_m, y_m from the equator] of a latitude and a longitude from the meridian. */
function tmForward(latRad, dlonRad) {
  const tauP = conformalTau(Math.tan(latRad), SERIES.e);
  const cosL = Math.cos(dlonRad);
  const xiP = Math.atan2(tauP, cosL);
  const etaP = Math.asinh(Math.sin(dlonRad) / Math.hypot(tauP, cosL));
  let xi = xiP;
  let eta = etaP;
  SERIES.alpha.forEach((a, i) => {
    const j2 = 2 * (i + 1);
    xi += a * Math.sin(j2 * xiP) * Math.cosh(j2 * etaP);
    eta += a * Math.cos(j2 * xiP) * Math.sinh(j2 * etaP);
  });
  return [SERIES.rectifyingM * eta, SERIES.rectifyingM * xi];
}

function tmReverse(xM, yM) {
  const xi = yM / SERIES.rectifyingM;
  const eta = xM / SERIES.rectifyingM;
  let xiP = xi;
  let etaP = eta;
  SERIES.beta.forEach((b, i) => {
    const j2 = 2 * (i + 1);
    xiP -= b * Math.sin(j2 * xi) * Math.cosh(j2 * eta);
    etaP -= b * Math.cos(j2 * xi) * Math.sinh(j2 * eta);
  });
  const sinhEtaP = Math.sinh(etaP);
  const cosXiP = Math.cos(xiP);
  const tauP = Math.sin(xiP) / Math.hypot(sinhEtaP, cosXiP);
  return [Math.atan(geodeticTau(tauP, SERIES.e)), Math.atan2(sinhEtaP, cosXiP)];
}

function wrapDeg(deg) {
  return ((((deg + 180) % 360) + 360) % 360) - 180;
}

export class LocalFrame {
  constructor(originLatDeg, originLonDeg) {
    this.originLatDeg = originLatDeg;
    this.originLonDeg = originLonDeg;
    this.originYM = tmForward(originLatDeg * RAD, 0)[1];
  }

  /** [east_m, north_m] of a latitude and longitude (deg). */
  toLocal(latDeg, lonDeg) {
    const [x, y] = tmForward(latDeg * RAD, wrapDeg(lonDeg - this.originLonDeg) * RAD);
    return [x, y - this.originYM];
  }

  /** [lat_deg, lon_deg] of a local point (m). */
  toGeodetic(eastM, northM) {
    const [lat, dlon] = tmReverse(eastM, northM + this.originYM);
    return [lat / RAD, wrapDeg(dlon / RAD + this.originLonDeg)];
  }
}
