// Live contacts over the WebSocket: `down` at once, at most one `move` per contact per
// animation frame (the newest position wins), `up` at once. Contacts still held when the
// connection comes back are touched down again.

export class LiveTouch {
  // settings(): {carrier, intensity, law} for the next `down` and `move`.
  constructor(session, settings) {
    this.session = session;
    this.settings = settings;
    this.prefix = `web-${Math.random().toString(36).slice(2, 8)}`;
    this.contacts = new Map();
    this.serial = 0;
    this.frame = 0;
    session.addEventListener("welcome", () => {
      for (const contact of this.contacts.values()) {
        if (!contact.stopped) this.sendDown(contact);
      }
    });
    // A refused `down` (its id is the contact's name): the contact never touched down,
    // so its moves would only be refused too.
    session.addEventListener("error", ({ detail }) => this.released([detail.id]));
  }

  down(id, pos) {
    const contact = { ...pos, name: this.freshName(id), pending: false, stopped: false };
    this.contacts.set(id, contact);
    this.sendDown(contact);
  }

  freshName(id) {
    this.serial += 1;
    return `${this.prefix}-${id}-${this.serial}`;
  }

  sendDown(contact) {
    const { carrier, intensity, law } = this.settings();
    this.session.send({
      type: "down", id: contact.name, contact: contact.name, x_cm: contact.x_cm,
      y_cm: contact.y_cm, intensity, carrier, law,
    });
  }

  move(id, pos) {
    const contact = this.contacts.get(id);
    if (!contact || contact.stopped) return;
    Object.assign(contact, pos, { pending: true });
    if (!this.frame) this.frame = requestAnimationFrame(() => this.flush());
  }

  flush() {
    this.frame = 0;
    const { intensity } = this.settings();
    for (const contact of this.contacts.values()) {
      if (!contact.pending) continue;
      contact.pending = false;
      this.session.send({
        type: "move", contact: contact.name, x_cm: contact.x_cm, y_cm: contact.y_cm,
        intensity,
      });
    }
  }

  // A new intensity reaches held contacts with their next `move`: send one now.
  nudge() {
    for (const contact of this.contacts.values()) {
      if (!contact.stopped) contact.pending = true;
    }
    if (this.contacts.size && !this.frame) this.frame = requestAnimationFrame(() => this.flush());
  }

  up(id) {
    const contact = this.contacts.get(id);
    if (!contact) return;
    this.contacts.delete(id);
    if (!contact.stopped) this.session.send({ type: "up", contact: contact.name });
  }

  // After a stop the server has dropped every contact: keep the held pointers quiet
  // until they are lifted and touch down again.
  stopped() {
    for (const contact of this.contacts.values()) {
      contact.stopped = true;
      contact.pending = false;
    }
  }

  // The service let go of some of our contacts (watchdog or a stop from elsewhere).
  released(names) {
    const gone = new Set(names);
    for (const contact of this.contacts.values()) {
      if (gone.has(contact.name)) {
        contact.stopped = true;
        contact.pending = false;
      }
    }
  }

  // A new carrier or law applies from the next touch; re-touch held contacts with it.
  retouch() {
    for (const [id, contact] of this.contacts) {
      if (contact.stopped) continue;
      this.session.send({ type: "up", contact: contact.name });
      contact.name = this.freshName(id);
      this.sendDown(contact);
    }
  }
}
