// A v4 client's side of the envelope, written from the description of tact-js 2.x
// (docs/bhaptics.md, "v4") with node's own crypto: a second implementation to check
// phantomtouch's against.
//
//   node v4_client.mjs hello SERVERKEY_JSON PLAINTEXT
//       -> {"clientKey": SdkClientKey JSON, "data": SdkData JSON of PLAINTEXT,
//           "aesKeyHex": the AES key, "rsaBits": the server key's size}
//   node v4_client.mjs open AES_KEY_HEX SDKDATA_JSON
//       -> the plaintext
//   node --experimental-websocket v4_client.mjs relay URL
//       a game over a real connection: answers the server's ServerKey with its own key,
//       then seals each stdin line {"send": PLAINTEXT} (or sends {"raw": TEXT} as it is,
//       closes on {"close": true}), and writes one JSON line per event to stdout:
//       {"keyed": RSA_BITS}, {"message": PLAINTEXT}, {"closed": CODE}

import { createInterface } from "node:readline";
import {
  constants,
  createCipheriv,
  createDecipheriv,
  createPublicKey,
  publicEncrypt,
  randomBytes,
} from "node:crypto";

function clientKey(serverKeyText) {
  const serverKey = JSON.parse(serverKeyText);
  if (serverKey.Type !== "ServerKey") throw new Error(`expected ServerKey, got ${serverKey.Type}`);
  const publicKey = createPublicKey({
    key: Buffer.from(serverKey.Key, "base64"),
    format: "der",
    type: "spki",
  });
  const aesKey = randomBytes(32);
  const sealedKey = publicEncrypt(
    { key: publicKey, padding: constants.RSA_PKCS1_PADDING },
    aesKey,
  );
  return {
    aesKey,
    message: JSON.stringify({ Type: "SdkClientKey", Key: sealedKey.toString("base64") }),
    rsaBits: publicKey.asymmetricKeyDetails.modulusLength,
  };
}

function relay(url) {
  const say = (event) => process.stdout.write(JSON.stringify(event) + "\n");
  const socket = new WebSocket(url);
  let aesKey = null;
  socket.onmessage = (event) => {
    const text = String(event.data);
    if (aesKey === null) {
      const key = clientKey(text);
      aesKey = key.aesKey;
      socket.send(key.message);
      say({ keyed: key.rsaBits });
      return;
    }
    say({ message: open(aesKey, text) });
  };
  socket.onclose = (event) => {
    say({ closed: event.code });
    process.exit(0);
  };
  createInterface({ input: process.stdin }).on("line", (line) => {
    const order = JSON.parse(line);
    if (order.close) socket.close(1000);
    else if (order.raw !== undefined) socket.send(order.raw);
    else socket.send(seal(aesKey, order.send));
  });
}

function seal(aesKey, plaintext) {
  const nonce = randomBytes(12);
  const cipher = createCipheriv("aes-256-gcm", aesKey, nonce);
  const body = Buffer.concat([cipher.update(plaintext, "utf8"), cipher.final()]);
  const data = Buffer.concat([nonce, body, cipher.getAuthTag()]).toString("base64");
  return JSON.stringify({ Type: "SdkData", Key: null, Data: data });
}

function open(aesKey, messageText) {
  const message = JSON.parse(messageText);
  if (message.Type !== "SdkData") throw new Error(`expected SdkData, got ${message.Type}`);
  const sealed = Buffer.from(message.Data, "base64");
  const decipher = createDecipheriv("aes-256-gcm", aesKey, sealed.subarray(0, 12));
  decipher.setAuthTag(sealed.subarray(sealed.length - 16));
  const body = sealed.subarray(12, sealed.length - 16);
  return Buffer.concat([decipher.update(body), decipher.final()]).toString("utf8");
}

const [mode, ...rest] = process.argv.slice(2);
if (mode === "hello") {
  const [serverKeyText, plaintext] = rest;
  const key = clientKey(serverKeyText);
  process.stdout.write(JSON.stringify({
    clientKey: key.message,
    data: seal(key.aesKey, plaintext),
    aesKeyHex: key.aesKey.toString("hex"),
    rsaBits: key.rsaBits,
  }));
} else if (mode === "open") {
  const [aesKeyHex, messageText] = rest;
  process.stdout.write(open(Buffer.from(aesKeyHex, "hex"), messageText));
} else if (mode === "relay") {
  relay(rest[0]);
} else {
  throw new Error(`unknown mode ${mode}`);
}
