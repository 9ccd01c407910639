// A small JSON reader and writer: enough for the phantomtouch protocol, no dependencies.
//
// Objects read as JsonObject (a Dictionary<string, object>), arrays as List<object>,
// numbers as double, and true/false/null as bool/null. Numbers are written with the
// invariant culture, so a machine set to a comma decimal separator still sends "1.5".
using System;
using System.Collections;
using System.Collections.Generic;
using System.Globalization;
using System.Text;

namespace PhantomTouch
{
    /// <summary>A JSON object with typed getters.</summary>
    public class JsonObject : Dictionary<string, object>
    {
        public JsonObject() : base(StringComparer.Ordinal) { }

        /// <summary>The string at <paramref name="key"/>, or null.</summary>
        public string GetString(string key)
        {
            object value;
            if (!TryGetValue(key, out value) || value == null) return null;
            return value as string ?? Convert.ToString(value, CultureInfo.InvariantCulture);
        }

        /// <summary>The number at <paramref name="key"/>, or <paramref name="fallback"/>.</summary>
        public double GetNumber(string key, double fallback = double.NaN)
        {
            object value;
            if (!TryGetValue(key, out value) || value == null) return fallback;
            if (value is double) return (double)value;
            return Convert.ToDouble(value, CultureInfo.InvariantCulture);
        }

        public JsonObject GetObject(string key)
        {
            object value;
            return TryGetValue(key, out value) ? value as JsonObject : null;
        }

        public List<object> GetArray(string key)
        {
            object value;
            return TryGetValue(key, out value) ? value as List<object> : null;
        }

        /// <summary>Adds a field and answers this object, for building messages inline.</summary>
        public JsonObject With(string key, object value)
        {
            this[key] = value;
            return this;
        }

        public override string ToString()
        {
            return Json.Serialize(this);
        }
    }

    /// <summary>Raised for text that is not JSON, or a value that JSON cannot hold.</summary>
    public class JsonException : FormatException
    {
        public JsonException(string message) : base(message) { }
    }

    public static class Json
    {
        public static string Serialize(object value)
        {
            var builder = new StringBuilder(128);
            Write(builder, value);
            return builder.ToString();
        }

        public static object Parse(string text)
        {
            if (text == null) throw new ArgumentNullException("text");
            var reader = new Reader(text);
            object value = reader.ReadValue();
            reader.SkipWhitespace();
            if (!reader.AtEnd) throw reader.Error("unexpected text after the value");
            return value;
        }

        /// <summary>Parses text that must hold a JSON object.</summary>
        public static JsonObject ParseObject(string text)
        {
            var value = Parse(text) as JsonObject;
            if (value == null) throw new JsonException("expected a JSON object");
            return value;
        }

        static void Write(StringBuilder b, object value)
        {
            if (value == null) { b.Append("null"); return; }
            var s = value as string;
            if (s != null) { WriteString(b, s); return; }
            if (value is bool) { b.Append((bool)value ? "true" : "false"); return; }
            if (value is double || value is float || value is decimal)
            {
                double d = Convert.ToDouble(value, CultureInfo.InvariantCulture);
                if (double.IsNaN(d) || double.IsInfinity(d))
                    throw new JsonException("JSON cannot hold " + d.ToString(CultureInfo.InvariantCulture));
                b.Append(d.ToString("R", CultureInfo.InvariantCulture));
                return;
            }
            if (value is int || value is long || value is short || value is byte || value is uint)
            {
                b.Append(Convert.ToInt64(value, CultureInfo.InvariantCulture).ToString(CultureInfo.InvariantCulture));
                return;
            }
            var dict = value as IDictionary;
            if (dict != null)
            {
                b.Append('{');
                bool first = true;
                foreach (DictionaryEntry entry in dict)
                {
                    if (!first) b.Append(',');
                    first = false;
                    WriteString(b, Convert.ToString(entry.Key, CultureInfo.InvariantCulture));
                    b.Append(':');
                    Write(b, entry.Value);
                }
                b.Append('}');
                return;
            }
            var list = value as IEnumerable;
            if (list != null)
            {
                b.Append('[');
                bool first = true;
                foreach (object item in list)
                {
                    if (!first) b.Append(',');
                    first = false;
                    Write(b, item);
                }
                b.Append(']');
                return;
            }
            throw new JsonException("cannot write a " + value.GetType().Name + " as JSON");
        }

        static void WriteString(StringBuilder b, string s)
        {
            b.Append('"');
            foreach (char c in s)
            {
                switch (c)
                {
                    case '"': b.Append("\\\""); break;
                    case '\\': b.Append("\\\\"); break;
                    case '\n': b.Append("\\n"); break;
                    case '\r': b.Append("\\r"); break;
                    case '\t': b.Append("\\t"); break;
                    default:
                        if (c < ' ') b.Append("\\u").Append(((int)c).ToString("x4", CultureInfo.InvariantCulture));
                        else b.Append(c);
                        break;
                }
            }
            b.Append('"');
        }

        sealed class Reader
        {
            readonly string text;
            int pos;

            public Reader(string text) { this.text = text; }

            public bool AtEnd { get { return pos >= text.Length; } }

            public JsonException Error(string what)
            {
                return new JsonException("JSON: " + what + " at offset " + pos);
            }

            public void SkipWhitespace()
            {
                while (pos < text.Length && char.IsWhiteSpace(text[pos])) pos++;
            }

            public object ReadValue()
            {
                SkipWhitespace();
                if (AtEnd) throw Error("unexpected end");
                char c = text[pos];
                if (c == '{') return ReadObject();
                if (c == '[') return ReadArray();
                if (c == '"') return ReadString();
                if (c == 't') return ReadWord("true", true);
                if (c == 'f') return ReadWord("false", false);
                if (c == 'n') return ReadWord("null", null);
                if (c == '-' || (c >= '0' && c <= '9')) return ReadNumber();
                throw Error("unexpected character '" + c + "'");
            }

            object ReadWord(string word, object value)
            {
                if (string.CompareOrdinal(text, pos, word, 0, word.Length) != 0) throw Error("expected " + word);
                pos += word.Length;
                return value;
            }

            double ReadNumber()
            {
                int start = pos;
                while (pos < text.Length && "+-0123456789.eE".IndexOf(text[pos]) >= 0) pos++;
                double value;
                if (!double.TryParse(text.Substring(start, pos - start), NumberStyles.Float,
                                     CultureInfo.InvariantCulture, out value))
                    throw Error("bad number");
                return value;
            }

            string ReadString()
            {
                pos++; // opening quote
                var b = new StringBuilder();
                while (true)
                {
                    if (AtEnd) throw Error("unterminated string");
                    char c = text[pos++];
                    if (c == '"') return b.ToString();
                    if (c != '\\') { b.Append(c); continue; }
                    if (AtEnd) throw Error("unterminated escape");
                    char e = text[pos++];
                    switch (e)
                    {
                        case '"': b.Append('"'); break;
                        case '\\': b.Append('\\'); break;
                        case '/': b.Append('/'); break;
                        case 'b': b.Append('\b'); break;
                        case 'f': b.Append('\f'); break;
                        case 'n': b.Append('\n'); break;
                        case 'r': b.Append('\r'); break;
                        case 't': b.Append('\t'); break;
                        case 'u':
                            if (pos + 4 > text.Length) throw Error("short \\u escape");
                            b.Append((char)int.Parse(text.Substring(pos, 4), NumberStyles.HexNumber,
                                                     CultureInfo.InvariantCulture));
                            pos += 4;
                            break;
                        default: throw Error("bad escape \\" + e);
                    }
                }
            }

            List<object> ReadArray()
            {
                pos++;
                var list = new List<object>();
                SkipWhitespace();
                if (!AtEnd && text[pos] == ']') { pos++; return list; }
                while (true)
                {
                    list.Add(ReadValue());
                    SkipWhitespace();
                    if (AtEnd) throw Error("unterminated array");
                    char c = text[pos++];
                    if (c == ']') return list;
                    if (c != ',') throw Error("expected , or ]");
                }
            }

            JsonObject ReadObject()
            {
                pos++;
                var obj = new JsonObject();
                SkipWhitespace();
                if (!AtEnd && text[pos] == '}') { pos++; return obj; }
                while (true)
                {
                    SkipWhitespace();
                    if (AtEnd || text[pos] != '"') throw Error("expected a key");
                    string key = ReadString();
                    SkipWhitespace();
                    if (AtEnd || text[pos] != ':') throw Error("expected :");
                    pos++;
                    obj[key] = ReadValue();
                    SkipWhitespace();
                    if (AtEnd) throw Error("unterminated object");
                    char c = text[pos++];
                    if (c == '}') return obj;
                    if (c != ',') throw Error("expected , or }");
                }
            }
        }
    }
}
