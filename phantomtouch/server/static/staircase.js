// Intensity matching of one actuator against the reference (docs/wearer.md): the levels the
// test interval may take, a 1-up-1-down staircase that places the trials, and the maximum
// likelihood fit of a psychometric function to all of them. Pure: no page, no requests.

export const STAIRCASE = {
  startStepDb: 4, // first step; halved at each reversal down to minStepDb
  minStepDb: 0.5,
  trials: 24, // trials per actuator
  atLimitTrials: 3, // answers pushing past the ceiling (or the floor) in a row end the actuator
  gapS: 0.25, // silence between the two intervals
};
// The reference interval is played this far below the device's ceiling: the headroom a
// weaker actuator's test interval may climb into.
export const REFERENCE_BELOW_MAX_DB = 14;
// The wearer profile's range (schema/wearer.py MAX_OFFSET_DB): the lowest test level.
export const OFFSET_LIMIT_DB = 20;
const FIT = {
  lapse: 0.04, // answers at random on this fraction of trials (half of them "test")
  pointsDb: { from: -20, to: 20, step: 0.05 },
  spreadsDb: [0.5, 0.75, 1, 1.5, 2, 3], // logistic scale of the psychometric function
};

// The levels of a run, all from the service's own ceiling (GET /device max_level_db, dB re
// 1 µm/s²): the one place a level is bounded. A test level is relative to the reference
// (dB); `absoluteDb` is what a touch asks for and never exceeds the ceiling.
export class Levels {
  constructor(maxLevelDb) {
    this.maxLevelDb = maxLevelDb;
    this.referenceDb = maxLevelDb - REFERENCE_BELOW_MAX_DB;
    this.ceilingDb = Math.min(OFFSET_LIMIT_DB, maxLevelDb - this.referenceDb);
    this.floorDb = -OFFSET_LIMIT_DB;
  }

  clamp(relativeDb) {
    return Math.min(this.ceilingDb, Math.max(this.floorDb, relativeDb));
  }

  absoluteDb(relativeDb) {
    return Math.min(this.maxLevelDb, this.referenceDb + this.clamp(relativeDb));
  }
}

// A small seeded generator (mulberry32): the interval order, repeatable for one wearer.
export function seededRandom(text) {
  let state = [...text].reduce((h, c) => Math.imul(h ^ c.charCodeAt(0), 2654435761) >>> 0, 1);
  return () => {
    state = (state + 0x6d2b79f5) >>> 0;
    let t = state;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

// One actuator's staircase: the level (dB re the reference) of its next test interval. Its
// state is a function of its answers alone, so a saved run replays into the same state.
export class Staircase {
  constructor(levels) {
    this.levels = levels;
    this.levelDb = 0;
    this.stepDb = STAIRCASE.startStepDb;
    this.lastDirection = 0;
    this.pushing = 0; // answers in a row asking past the ceiling or the floor
    this.records = [];
  }

  get done() {
    return this.records.length >= STAIRCASE.trials || this.pushing >= STAIRCASE.atLimitTrials;
  }

  // "ceiling": felt weaker than the reference even at the device's ceiling; "floor":
  // stronger even at the lowest level; null: matched within the range.
  get limit() {
    if (this.pushing < STAIRCASE.atLimitTrials) return null;
    return this.records[this.records.length - 1][1] ? "floor" : "ceiling";
  }

  // Trials this actuator still needs at most.
  get remaining() {
    return this.done ? 0 : STAIRCASE.trials - this.records.length;
  }

  // The test was judged stronger: step down; weaker: step up.
  answer(testStronger) {
    const { ceilingDb, floorDb } = this.levels;
    this.records.push([this.levelDb, testStronger]);
    const past = testStronger ? this.levelDb <= floorDb : this.levelDb >= ceilingDb;
    this.pushing = past ? this.pushing + 1 : 0;
    const direction = testStronger ? -1 : 1;
    if (this.lastDirection !== 0 && direction !== this.lastDirection) {
      this.stepDb = Math.max(STAIRCASE.minStepDb, this.stepDb / 2);
    }
    this.lastDirection = direction;
    this.levelDb = this.levels.clamp(this.levelDb + direction * this.stepDb);
  }

  // The level felt as strong as the reference, within the levels' range: P(test stronger)
  // = lapse / 2 + (1 - lapse) / (1 + exp(-(level - match) / spread)), match and spread by
  // maximum likelihood on a grid.
  estimateDb() {
    let best = { logLikelihood: -Infinity, matchDb: 0 };
    const { from, to, step } = FIT.pointsDb;
    for (const spread of FIT.spreadsDb) {
      for (let i = 0; from + i * step <= to; i += 1) {
        const matchDb = from + i * step;
        let logLikelihood = 0;
        for (const [levelDb, testStronger] of this.records) {
          const p = FIT.lapse / 2 + (1 - FIT.lapse) / (1 + Math.exp(-(levelDb - matchDb) / spread));
          logLikelihood += Math.log(testStronger ? p : 1 - p);
        }
        if (logLikelihood > best.logLikelihood) best = { logLikelihood, matchDb };
      }
    }
    return this.levels.clamp(best.matchDb);
  }
}
