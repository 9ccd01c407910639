// REST for the console harness: the IHttpTransport of PhantomTouchClient over HttpClient
// (the Unity scripts use UnityWebRequestTransport; everything above the transport is shared).
using System;
using System.Collections.Generic;
using System.Net.Http;
using System.Text;
using System.Threading.Tasks;

namespace PhantomTouch.Harness
{
    public sealed class HttpClientTransport : IHttpTransport
    {
        static readonly HttpClient http = new HttpClient { Timeout = TimeSpan.FromSeconds(10) };

        public async Task<HttpAnswer> SendAsync(string method, string url, string jsonBody, IDictionary<string, string> headers)
        {
            var request = new HttpRequestMessage(new HttpMethod(method), url);
            if (jsonBody != null) request.Content = new StringContent(jsonBody, Encoding.UTF8, "application/json");
            foreach (var header in headers) request.Headers.TryAddWithoutValidation(header.Key, header.Value);
            try
            {
                using (var response = await http.SendAsync(request).ConfigureAwait(false))
                {
                    var body = await response.Content.ReadAsByteArrayAsync().ConfigureAwait(false);
                    return new HttpAnswer { Status = (int)response.StatusCode, Body = body };
                }
            }
            catch (HttpRequestException e)
            {
                return new HttpAnswer { Error = e.GetBaseException().Message };
            }
            catch (TaskCanceledException)
            {
                return new HttpAnswer { Error = "no answer within " + http.Timeout.TotalSeconds + " s" };
            }
        }
    }
}
